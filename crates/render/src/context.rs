//! The GPU device: one adapter, device and queue, headless or compatible with a window surface.

use super::{RenderError, Result};

/// A wgpu instance, adapter, device and queue.
#[derive(Debug)]
pub struct GpuContext {
    /// The instance the adapter came from (surfaces are created from it).
    pub instance: wgpu::Instance,
    /// The adapter (on a machine without a GPU: Mesa lavapipe, a Vulkan driver on the CPU).
    pub adapter: wgpu::Adapter,
    /// The logical device.
    pub device: wgpu::Device,
    /// Its queue.
    pub queue: wgpu::Queue,
}

impl GpuContext {
    /// A device for offscreen rendering. `WGPU_BACKEND=vulkan|gl` picks a backend.
    ///
    /// # Errors
    /// [`RenderError::NoAdapter`] when no adapter exists (no Vulkan/GL driver installed), or
    /// [`RenderError::Device`] when the device cannot be created.
    pub fn headless() -> Result<Self> {
        let instance =
            wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        pollster::block_on(Self::with_instance(instance, None))
    }

    /// A device on `instance` able to present to `surface` (when given).
    ///
    /// # Errors
    /// As [`GpuContext::headless`].
    pub async fn with_instance(
        instance: wgpu::Instance,
        surface: Option<&wgpu::Surface<'_>>,
    ) -> Result<Self> {
        let adapter = instance
            .request_adapter(&wgpu::RequestAdapterOptions {
                power_preference: wgpu::PowerPreference::HighPerformance,
                force_fallback_adapter: false,
                compatible_surface: surface,
                apply_limit_buckets: false,
            })
            .await
            .map_err(|e| RenderError::NoAdapter(e.to_string()))?;
        let (device, queue) = adapter
            .request_device(&wgpu::DeviceDescriptor {
                label: Some("btfmrf"),
                required_limits: adapter.limits(),
                ..Default::default()
            })
            .await
            .map_err(|e| RenderError::Device(e.to_string()))?;
        Ok(Self {
            instance,
            adapter,
            device,
            queue,
        })
    }

    /// The adapter's name and backend, e.g. "llvmpipe (LLVM 15.0.6, 256 bits) (Vulkan)".
    pub fn describe(&self) -> String {
        let info = self.adapter.get_info();
        format!("{} ({:?})", info.name, info.backend)
    }

    /// Runs `f` and turns any validation or out-of-memory error it raised into
    /// [`RenderError::Device`] instead of a panic.
    pub(crate) fn checked<T>(&self, what: &str, f: impl FnOnce() -> T) -> Result<T> {
        let validation = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let memory = self.device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let value = f();
        let oom = pollster::block_on(memory.pop());
        let invalid = pollster::block_on(validation.pop());
        match oom.or(invalid) {
            Some(e) => Err(RenderError::Device(format!("{what}: {e}"))),
            None => Ok(value),
        }
    }
}
