//! Frames and readback: render targets, one cleared render pass, and copying a texture back
//! to the CPU. Shared by the headless renderer and the viewer, whatever the material.

use ndarray::Array3;

use super::{GpuContext, MAX_RENDER_SIDE, RenderError, Result};

/// The colour format of offscreen targets: linear float, read back exactly.
pub const TARGET_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba32Float;

/// The depth buffer format of every pipeline.
pub const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

/// Checks an image size.
///
/// # Errors
/// A side of zero or beyond [`MAX_RENDER_SIDE`].
pub fn check_size(width: u32, height: u32) -> Result<()> {
    if width == 0 || height == 0 || width > MAX_RENDER_SIDE || height > MAX_RENDER_SIDE {
        return Err(RenderError::parameter(
            "--size",
            format!("{width}x{height} is outside 1..={MAX_RENDER_SIDE} pixels a side"),
        ));
    }
    Ok(())
}

/// A `width` x `height` depth buffer ([`DEPTH_FORMAT`]; sides of 0 become 1).
pub fn depth_texture(ctx: &GpuContext, width: u32, height: u32) -> wgpu::Texture {
    ctx.device.create_texture(&wgpu::TextureDescriptor {
        label: Some("depth"),
        size: wgpu::Extent3d {
            width: width.max(1),
            height: height.max(1),
            depth_or_array_layers: 1,
        },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: DEPTH_FORMAT,
        usage: wgpu::TextureUsages::RENDER_ATTACHMENT,
        view_formats: &[],
    })
}

/// Records one frame into `encoder`: clears colour (black) and depth, then `draw`s.
pub fn encode_frame(
    encoder: &mut wgpu::CommandEncoder,
    colour: &wgpu::TextureView,
    depth: &wgpu::TextureView,
    draw: impl FnOnce(&mut wgpu::RenderPass<'_>),
) {
    let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
        label: Some("frame"),
        color_attachments: &[Some(wgpu::RenderPassColorAttachment {
            view: colour,
            depth_slice: None,
            resolve_target: None,
            ops: wgpu::Operations {
                load: wgpu::LoadOp::Clear(wgpu::Color::BLACK),
                store: wgpu::StoreOp::Store,
            },
        })],
        depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
            view: depth,
            depth_ops: Some(wgpu::Operations {
                load: wgpu::LoadOp::Clear(1.0),
                store: wgpu::StoreOp::Discard,
            }),
            stencil_ops: None,
        }),
        timestamp_writes: None,
        occlusion_query_set: None,
        multiview_mask: None,
    });
    draw(&mut pass);
}

/// Copies a 2D texture (usage `COPY_SRC`, `bytes_per_pixel` per texel) to the CPU: rows
/// without padding, top row first. Waits for the GPU.
///
/// # Errors
/// A device error.
pub fn read_texture(
    ctx: &GpuContext,
    texture: &wgpu::Texture,
    bytes_per_pixel: u32,
) -> Result<Vec<u8>> {
    let (w, h) = (texture.width(), texture.height());
    let row_bytes = w * bytes_per_pixel;
    let padded = row_bytes.div_ceil(256) * 256;
    let readback = ctx.checked("readback buffer", || {
        ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size: u64::from(padded) * u64::from(h),
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        })
    })?;
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    encoder.copy_texture_to_buffer(
        wgpu::TexelCopyTextureInfo {
            texture,
            mip_level: 0,
            origin: wgpu::Origin3d::ZERO,
            aspect: wgpu::TextureAspect::All,
        },
        wgpu::TexelCopyBufferInfo {
            buffer: &readback,
            layout: wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(padded),
                rows_per_image: Some(h),
            },
        },
        wgpu::Extent3d {
            width: w,
            height: h,
            depth_or_array_layers: 1,
        },
    );
    ctx.queue.submit([encoder.finish()]);
    let slice = readback.slice(..);
    let (tx, rx) = std::sync::mpsc::channel();
    slice.map_async(wgpu::MapMode::Read, move |r| {
        let _ = tx.send(r);
    });
    let device_error = |e: String| RenderError::Device(e);
    ctx.device
        .poll(wgpu::PollType::wait_indefinitely())
        .map_err(|e| device_error(e.to_string()))?;
    rx.recv()
        .map_err(|e| device_error(e.to_string()))?
        .map_err(|e| device_error(e.to_string()))?;
    let data = slice
        .get_mapped_range()
        .map_err(|e| device_error(e.to_string()))?;
    let mut out = Vec::with_capacity((row_bytes * h) as usize);
    for y in 0..h as usize {
        out.extend_from_slice(&data[y * padded as usize..y * padded as usize + row_bytes as usize]);
    }
    drop(data);
    readback.unmap();
    Ok(out)
}

/// Renders one offscreen frame of `width` x `height` ([`TARGET_FORMAT`], black background)
/// whose uniforms are written already: clears, `draw`s, reads back as linear RGB, planar
/// (3, height, width).
///
/// # Errors
/// An invalid size or a device error.
pub fn render_offscreen(
    ctx: &GpuContext,
    (width, height): (u32, u32),
    draw: impl FnOnce(&mut wgpu::RenderPass<'_>),
) -> Result<Array3<f32>> {
    check_size(width, height)?;
    let colour = ctx.checked("render target", || {
        ctx.device.create_texture(&wgpu::TextureDescriptor {
            label: Some("target"),
            size: wgpu::Extent3d {
                width,
                height,
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: TARGET_FORMAT,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        })
    })?;
    let depth = depth_texture(ctx, width, height);
    let colour_view = colour.create_view(&Default::default());
    let depth_view = depth.create_view(&Default::default());
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    encode_frame(&mut encoder, &colour_view, &depth_view, draw);
    ctx.queue.submit([encoder.finish()]);
    let data = read_texture(ctx, &colour, 16)?;
    let (w, h) = (width as usize, height as usize);
    let mut image = Array3::<f32>::zeros((3, h, w));
    for (i, texel) in data.chunks_exact(16).enumerate() {
        for c in 0..3 {
            let v = &texel[4 * c..4 * c + 4];
            image[[c, i / w, i % w]] = f32::from_le_bytes([v[0], v[1], v[2], v[3]]);
        }
    }
    Ok(image)
}
