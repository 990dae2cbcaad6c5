//! The interactive viewer: a winit window (winit 0.30 `ApplicationHandler`), an orbit camera
//! (left drag, wheel), the light on the arrow keys or right drag, `B` / `D` for bump /
//! displacement mapping, `M` for the next mesh; frame time in the window title.
//!
//! The viewer synthesizes every cluster once at start (at [`ViewerOptions::tile`]),
//! since the camera and light can go anywhere. `--screenshot FILE --frames N` renders N
//! frames, saves the window's contents and exits (used by the tests under Xvfb).

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

use winit::application::ApplicationHandler;
use winit::dpi::PhysicalSize;
use winit::event::{ElementState, MouseButton, MouseScrollDelta, WindowEvent};
use winit::event_loop::{ActiveEventLoop, ControlFlow, EventLoop};
use winit::keyboard::{KeyCode, PhysicalKey};
use winit::window::{Window, WindowId};

use super::frame::{depth_texture, encode_frame, read_texture};
use super::mesh::MeshKind;
use super::mrf::{GpuMaterial, MaterialTables, MrfPass};
use super::pipeline::GpuMesh;
use super::scene::{Camera, Light, Scene};
use super::{GpuContext, Mapping, RenderError, Result, check_tile};
use btfmrf::btf::Direction;
use btfmrf::model::MaterialModel;
use btfmrf::progress::Progress;
use btfmrf::synthesis::SynthesisOptions;

/// Options of [`run_viewer`].
#[derive(Debug, Clone)]
pub struct ViewerOptions {
    /// Window size, pixels.
    pub width: u32,
    /// See `width`.
    pub height: u32,
    /// Measured texels per texture repetition, the side of the synthesized textures (checked
    /// by [`check_tile`], like `render --tile`).
    pub tile: usize,
    /// Synthesis seed.
    pub seed: u64,
    /// The meshes `M` cycles through; the first is shown first.
    pub meshes: Vec<MeshKind>,
    /// The mapping shown first.
    pub mapping: Mapping,
    /// Initial camera and light.
    pub view: Direction,
    /// See `view`.
    pub light: Direction,
    /// Render this many frames, then exit.
    pub frames: Option<u64>,
    /// After the last frame, save the window's contents here (PNG).
    pub screenshot: Option<PathBuf>,
}

/// Everything that lives while the window is open.
struct Viewer {
    window: Arc<Window>,
    surface: wgpu::Surface<'static>,
    config: wgpu::SurfaceConfiguration,
    ctx: GpuContext,
    pass: MrfPass,
    material: GpuMaterial,
    meshes: Vec<(GpuMesh, GpuMesh)>,
    mesh: usize,
    depth: wgpu::Texture,
    copy_src: bool,
}

struct App<'a> {
    model: &'a MaterialModel,
    /// Counts the subspace images and the pairs' finishes made before the first frame.
    progress: &'a dyn Progress,
    options: ViewerOptions,
    viewer: Option<Viewer>,
    error: Option<RenderError>,
    mapping: Mapping,
    camera: Camera,
    light: Light,
    drag: Option<(MouseButton, (f64, f64))>,
    cursor: (f64, f64),
    frames: u64,
    last_title: Instant,
    frame_ms: f64,
}

impl App<'_> {
    fn start(&mut self, event_loop: &ActiveEventLoop) -> Result<Viewer> {
        let o = &self.options;
        let window = Arc::new(
            event_loop
                .create_window(
                    Window::default_attributes()
                        .with_title("btfmrf view")
                        .with_inner_size(PhysicalSize::new(o.width, o.height)),
                )
                .map_err(|e| RenderError::Window(e.to_string()))?,
        );
        let instance =
            wgpu::Instance::new(wgpu::InstanceDescriptor::new_with_display_handle_from_env(
                Box::new(event_loop.owned_display_handle()),
            ));
        let surface = instance
            .create_surface(window.clone())
            .map_err(|e| RenderError::Window(e.to_string()))?;
        let ctx = pollster::block_on(GpuContext::with_instance(instance, Some(&surface)))?;
        let caps = surface.get_capabilities(&ctx.adapter);
        let format = caps
            .formats
            .iter()
            .copied()
            .find(|f| f.is_srgb())
            .or_else(|| caps.formats.first().copied())
            .ok_or_else(|| RenderError::Window("the surface supports no format".into()))?;
        let copy_src = caps.usages.contains(wgpu::TextureUsages::COPY_SRC);
        let size = window.inner_size();
        let config = wgpu::SurfaceConfiguration {
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT
                | if copy_src {
                    wgpu::TextureUsages::COPY_SRC
                } else {
                    wgpu::TextureUsages::empty()
                },
            format,
            width: size.width.max(1),
            height: size.height.max(1),
            present_mode: wgpu::PresentMode::AutoVsync,
            desired_maximum_frame_latency: 2,
            alpha_mode: caps.alpha_modes[0],
            view_formats: vec![],
            color_space: wgpu::SurfaceColorSpace::Auto,
        };
        surface.configure(&ctx.device, &config);
        let pass = MrfPass::new(&ctx, format)?;
        let model = self.model;
        let all: Vec<usize> = (0..model.subspaces().len()).collect();
        let n = o.tile;
        let cache = model.synthesis_cache_for(
            &all,
            &SynthesisOptions {
                rows: n,
                cols: n,
                seed: o.seed,
                tileable: true,
            },
            self.progress,
        )?;
        // Camera and light go anywhere: every pair with parts of its own is finished.
        let own = model.pairs_with_own_parts();
        let tables = MaterialTables::new(model, &cache, None, &own, self.progress)?;
        let material = GpuMaterial::new(&ctx, &pass, &cache, &tables)?;
        let mut meshes = Vec::new();
        for kind in &o.meshes {
            meshes.push((
                GpuMesh::new(&ctx, &kind.build(64, 1.0)?),
                GpuMesh::new(&ctx, &kind.build(256, 1.0)?),
            ));
        }
        let depth = depth_texture(&ctx, config.width, config.height);
        Ok(Viewer {
            window,
            surface,
            config,
            ctx,
            pass,
            material,
            meshes,
            mesh: 0,
            depth,
            copy_src,
        })
    }

    /// Renders one frame to the window; after the last one of `--frames`, saves the
    /// screenshot and returns `true` (exit).
    fn frame(&mut self) -> Result<bool> {
        let Some(v) = self.viewer.as_mut() else {
            return Ok(false);
        };
        let started = Instant::now();
        let frame = match v.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(t)
            | wgpu::CurrentSurfaceTexture::Suboptimal(t) => t,
            wgpu::CurrentSurfaceTexture::Timeout | wgpu::CurrentSurfaceTexture::Occluded => {
                return Ok(false);
            }
            _ => {
                v.surface.configure(&v.ctx.device, &v.config);
                return Ok(false);
            }
        };
        let scene = Scene {
            camera: self.camera,
            light: self.light,
            width: v.config.width,
            height: v.config.height,
        };
        let material = &v.material;
        let mesh = match self.mapping {
            Mapping::Displacement => &v.meshes[v.mesh].1,
            Mapping::Bump | Mapping::Plain => &v.meshes[v.mesh].0,
        };
        material.set_frame(&v.ctx, &scene, mesh);
        let view = frame.texture.create_view(&Default::default());
        let depth_view = v.depth.create_view(&Default::default());
        let mut encoder = v.ctx.device.create_command_encoder(&Default::default());
        let mapping = self.mapping;
        encode_frame(&mut encoder, &view, &depth_view, |pass| {
            v.pass.draw(pass, mapping, material, mesh)
        });
        v.ctx.queue.submit([encoder.finish()]);
        // Wait for the GPU so that the title shows the real frame time, not the submission's.
        v.ctx
            .device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| RenderError::Device(e.to_string()))?;
        self.frames += 1;
        let last = self.options.frames.is_some_and(|n| self.frames >= n);
        if last && let Some(path) = self.options.screenshot.clone() {
            let texture = if v.copy_src {
                frame.texture.clone()
            } else {
                // The surface cannot be read: render the same frame offscreen.
                let t = v.ctx.device.create_texture(&wgpu::TextureDescriptor {
                    label: Some("screenshot"),
                    size: frame.texture.size(),
                    mip_level_count: 1,
                    sample_count: 1,
                    dimension: wgpu::TextureDimension::D2,
                    format: v.config.format,
                    usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
                    view_formats: &[],
                });
                let tv = t.create_view(&Default::default());
                let mut encoder = v.ctx.device.create_command_encoder(&Default::default());
                encode_frame(&mut encoder, &tv, &depth_view, |pass| {
                    v.pass.draw(pass, mapping, material, mesh)
                });
                v.ctx.queue.submit([encoder.finish()]);
                t
            };
            save_screenshot(&v.ctx, &texture, v.config.format, &path)?;
        }
        v.ctx.queue.present(frame);
        let ms = started.elapsed().as_secs_f64() * 1e3;
        self.frame_ms = if self.frame_ms == 0.0 {
            ms
        } else {
            0.8 * self.frame_ms + 0.2 * ms
        };
        if self.last_title.elapsed().as_secs_f64() > 0.25 || last {
            self.last_title = Instant::now();
            v.window.set_title(&format!(
                "btfmrf view - {} on {} - {:.1} ms/frame - light {:.0},{:.0} (arrows/right drag; B/D mapping, M mesh)",
                self.mapping,
                self.options.meshes[v.mesh],
                self.frame_ms,
                self.light.direction.theta_deg,
                self.light.direction.phi_deg
            ));
        }
        Ok(last)
    }

    fn redraw(&self) {
        if let Some(v) = &self.viewer {
            v.window.request_redraw();
        }
    }

    fn fail(&mut self, event_loop: &ActiveEventLoop, e: RenderError) {
        self.error = Some(e);
        event_loop.exit();
    }
}

/// Writes an 8-bit RGBA or BGRA texture as an RGB PNG.
fn save_screenshot(
    ctx: &GpuContext,
    texture: &wgpu::Texture,
    format: wgpu::TextureFormat,
    path: &std::path::Path,
) -> Result<()> {
    let bgra = matches!(
        format,
        wgpu::TextureFormat::Bgra8Unorm | wgpu::TextureFormat::Bgra8UnormSrgb
    );
    let rgba = matches!(
        format,
        wgpu::TextureFormat::Rgba8Unorm | wgpu::TextureFormat::Rgba8UnormSrgb
    );
    if !bgra && !rgba {
        return Err(RenderError::Window(format!(
            "cannot save a screenshot of a {format:?} surface"
        )));
    }
    let data = read_texture(ctx, texture, 4)?;
    let rgb: Vec<u8> = data
        .chunks_exact(4)
        .flat_map(|p| {
            if bgra {
                [p[2], p[1], p[0]]
            } else {
                [p[0], p[1], p[2]]
            }
        })
        .collect();
    let image = image::RgbImage::from_raw(texture.width(), texture.height(), rgb)
        .ok_or_else(|| RenderError::Window("screenshot size".into()))?;
    image
        .save(path)
        .map_err(|e| RenderError::Window(format!("writing {}: {e}", path.display())))
}

impl ApplicationHandler for App<'_> {
    fn resumed(&mut self, event_loop: &ActiveEventLoop) {
        if self.viewer.is_some() {
            return;
        }
        match self.start(event_loop) {
            Ok(v) => {
                v.window.request_redraw();
                self.viewer = Some(v);
            }
            Err(e) => self.fail(event_loop, e),
        }
    }

    fn window_event(&mut self, event_loop: &ActiveEventLoop, _id: WindowId, event: WindowEvent) {
        match event {
            WindowEvent::CloseRequested => event_loop.exit(),
            WindowEvent::Resized(size) => {
                if let Some(v) = self.viewer.as_mut()
                    && size.width > 0
                    && size.height > 0
                {
                    v.config.width = size.width;
                    v.config.height = size.height;
                    v.surface.configure(&v.ctx.device, &v.config);
                    v.depth = depth_texture(&v.ctx, size.width, size.height);
                }
                self.redraw();
            }
            WindowEvent::RedrawRequested => match self.frame() {
                Ok(true) => event_loop.exit(),
                Ok(false) => {
                    if self.options.frames.is_some() {
                        self.redraw();
                    }
                }
                Err(e) => self.fail(event_loop, e),
            },
            WindowEvent::KeyboardInput { event, .. } if event.state == ElementState::Pressed => {
                let l = &mut self.light.direction;
                match event.physical_key {
                    PhysicalKey::Code(KeyCode::ArrowUp) => {
                        *l = Direction::new((l.theta_deg - 5.0).max(0.0), l.phi_deg)
                    }
                    PhysicalKey::Code(KeyCode::ArrowDown) => {
                        *l = Direction::new((l.theta_deg + 5.0).min(89.0), l.phi_deg)
                    }
                    PhysicalKey::Code(KeyCode::ArrowLeft) => {
                        *l = Direction::new(l.theta_deg, l.phi_deg + 10.0)
                    }
                    PhysicalKey::Code(KeyCode::ArrowRight) => {
                        *l = Direction::new(l.theta_deg, l.phi_deg - 10.0)
                    }
                    PhysicalKey::Code(KeyCode::KeyB) => self.mapping = Mapping::Bump,
                    PhysicalKey::Code(KeyCode::KeyD) => self.mapping = Mapping::Displacement,
                    PhysicalKey::Code(KeyCode::KeyM) => {
                        if let Some(v) = self.viewer.as_mut() {
                            v.mesh = (v.mesh + 1) % v.meshes.len();
                        }
                    }
                    PhysicalKey::Code(KeyCode::Escape | KeyCode::KeyQ) => event_loop.exit(),
                    _ => {}
                }
                self.redraw();
            }
            WindowEvent::MouseInput { state, button, .. } => {
                self.drag = (state == ElementState::Pressed).then_some((button, self.cursor));
            }
            WindowEvent::CursorMoved { position, .. } => {
                self.cursor = (position.x, position.y);
                if let Some((button, from)) = self.drag {
                    let (dx, dy) = (position.x - from.0, position.y - from.1);
                    self.drag = Some((button, self.cursor));
                    let d = match button {
                        MouseButton::Right => &mut self.light.direction,
                        _ => &mut self.camera.direction,
                    };
                    *d = Direction::new(
                        (d.theta_deg + 0.4 * dy).clamp(0.0, 89.0),
                        d.phi_deg - 0.4 * dx,
                    );
                    self.redraw();
                }
            }
            WindowEvent::MouseWheel { delta, .. } => {
                let step = match delta {
                    MouseScrollDelta::LineDelta(_, y) => y,
                    MouseScrollDelta::PixelDelta(p) => p.y as f32 / 40.0,
                };
                self.camera.distance = (self.camera.distance * 0.9f32.powf(step)).clamp(1.5, 20.0);
                self.redraw();
            }
            _ => {}
        }
    }
}

/// Opens the viewer window on `model` and runs until it is closed (or, with
/// [`ViewerOptions::frames`], until that many frames are drawn); `progress` counts the
/// subspace images and the pairs' finishes made before the first frame.
///
/// # Errors
/// No display (`DISPLAY`/`WAYLAND_DISPLAY` unset), no adapter, a synthesis or device error.
pub fn run_viewer(
    model: &MaterialModel,
    options: ViewerOptions,
    progress: &dyn Progress,
) -> Result<()> {
    if options.meshes.is_empty() {
        return Err(RenderError::parameter("--mesh", "no mesh to show"));
    }
    check_tile(model, options.tile)?;
    let event_loop = EventLoop::new().map_err(|e| RenderError::Window(e.to_string()))?;
    event_loop.set_control_flow(ControlFlow::Wait);
    let mut app = App {
        model,
        progress,
        mapping: options.mapping,
        camera: Camera::orbit(options.view, 3.5),
        light: Light {
            direction: options.light,
            distance: Some(4.0),
        },
        options,
        viewer: None,
        error: None,
        drag: None,
        cursor: (0.0, 0.0),
        frames: 0,
        last_title: Instant::now(),
        frame_ms: 0.0,
    };
    event_loop
        .run_app(&mut app)
        .map_err(|e| RenderError::Window(e.to_string()))?;
    match app.error {
        Some(e) => Err(e),
        None => Ok(()),
    }
}
