//! Offscreen rendering to linear RGB images, and the whole "model -> picture" job.

use std::time::Instant;

use ndarray::Array3;

use super::lpca::GpuLpca;
use super::lut::DirectionLut;
use super::mesh::Mesh;
use super::pipeline::{DEPTH_FORMAT, GpuMaterial, GpuMesh, MaterialTables, Pipelines};
use super::plan::{ScenePlan, plan_scene};
use super::scene::Scene;
use super::{GpuContext, MAX_RENDER_SIDE, Mapping, RenderError, Result};
use btfmrf::lpca::LpcaModel;
use btfmrf::model::MaterialModel;
use btfmrf::synthesis::{SynthesisCache, SynthesisOptions};
use rayon::prelude::*;

/// The coarsest texture side the footprint may choose, texels.
const MIN_TEXTURE_SIDE: usize = 16;

/// The colour format of offscreen targets: linear float, read back exactly.
pub const TARGET_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba32Float;

/// A device and the pipelines for offscreen targets.
#[derive(Debug)]
pub struct Renderer {
    /// The device.
    pub ctx: GpuContext,
    /// The pipelines (for [`TARGET_FORMAT`]).
    pub pipelines: Pipelines,
}

/// A rendered picture and what it cost.
#[derive(Debug, Clone)]
pub struct RenderOutput {
    /// Linear RGB, planar (3, height, width).
    pub image: Array3<f32>,
    /// The plan: clusters synthesized and texture side on the GPU.
    pub plan: ScenePlan,
    /// Side of the synthesized tile, measured texels (one texture repetition).
    pub tile: usize,
    /// Subspace images in the model.
    pub subspaces_total: usize,
    /// Subspace images synthesized for this frame (all of the plan's, except those a cache
    /// held already).
    pub subspaces_synthesized: usize,
    /// Texels synthesized (subspace images x side^2).
    pub texels_synthesized: u64,
    /// Seconds spent synthesizing subspace images and range map.
    pub synthesis_seconds: f64,
    /// Seconds spent uploading, rendering and reading back the frame.
    pub render_seconds: f64,
    /// The adapter, e.g. "llvmpipe (LLVM 15.0.6, 256 bits) (Vulkan)".
    pub adapter: String,
}

/// Options of [`Renderer::render_model`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ModelRenderOptions {
    /// The mapping.
    pub mapping: Mapping,
    /// Seed of the synthesis.
    pub seed: u64,
    /// A fixed texture side on the GPU (a power of two, at most `tile`); `None` chooses it
    /// from the screen footprint. It sets how finely the tile is sampled, never how large
    /// the material appears.
    pub texture_size: Option<usize>,
    /// The largest texture side chosen from the footprint.
    pub max_texture_size: usize,
    /// Measured texels per texture repetition (a power of two): the material's physical
    /// scale on the mesh. The subspace images and the range map are synthesized at this
    /// side whatever the texture resolution, so the relief's lateral size and height per
    /// unit of surface do not change with distance or `texture_size`.
    pub tile: usize,
}

/// The default [`ModelRenderOptions::tile`], measured texels per texture repetition.
pub const DEFAULT_TILE: usize = 512;

impl Default for ModelRenderOptions {
    fn default() -> Self {
        Self {
            mapping: Mapping::Bump,
            seed: 1,
            texture_size: None,
            max_texture_size: 2048,
            tile: DEFAULT_TILE,
        }
    }
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

impl Renderer {
    /// A headless device and its pipelines.
    ///
    /// # Errors
    /// No adapter, or a device or shader error.
    pub fn new() -> Result<Self> {
        let ctx = GpuContext::headless()?;
        let pipelines = Pipelines::new(&ctx, TARGET_FORMAT)?;
        Ok(Self { ctx, pipelines })
    }

    /// Renders `mesh` with `material` to a linear RGB image (black background).
    ///
    /// # Errors
    /// An invalid size or a device error.
    pub fn render(
        &self,
        material: &GpuMaterial,
        mesh: &GpuMesh,
        scene: &Scene,
        mapping: Mapping,
    ) -> Result<Array3<f32>> {
        if mapping == Mapping::Lpca {
            return Err(RenderError::Unsupported(
                "the lpca pipeline renders LPCA models (Renderer::render_lpca)".into(),
            ));
        }
        check_size(scene.width, scene.height)?;
        material.set_frame(&self.ctx, scene, mesh, 0);
        self.render_frame(scene, |pass| {
            self.pipelines.draw(pass, mapping, material, mesh)
        })
    }

    /// Renders `mesh` with an LPCA model on the GPU to a linear RGB image (black background).
    ///
    /// # Errors
    /// An invalid size or a device error.
    pub fn render_gpu_lpca(
        &self,
        model: &GpuLpca,
        mesh: &GpuMesh,
        scene: &Scene,
    ) -> Result<Array3<f32>> {
        check_size(scene.width, scene.height)?;
        model.set_frame(&self.ctx, scene, mesh);
        self.render_frame(scene, |pass| self.pipelines.draw_lpca(pass, model, mesh))
    }

    /// The whole LPCA job: uploads `model` (cluster indices, weights, eigen-ABRDFs and the
    /// direction tables) and renders one frame, every fragment decoding its texel. Nothing is
    /// synthesized; the plan lists all clusters and the model's width as texture size.
    ///
    /// # Errors
    /// An invalid size, a PCA BTF model, a model beyond the device's limits or a device error.
    pub fn render_lpca(
        &self,
        model: &LpcaModel,
        mesh: &Mesh,
        scene: &Scene,
    ) -> Result<RenderOutput> {
        check_size(scene.width, scene.height)?;
        let start = Instant::now();
        let luts = (
            DirectionLut::new(model.views())?,
            DirectionLut::new(model.lights())?,
        );
        let gpu = GpuLpca::new(&self.ctx, &self.pipelines, model, &luts)?;
        let gpu_mesh = GpuMesh::new(&self.ctx, mesh);
        let image = self.render_gpu_lpca(&gpu, &gpu_mesh, scene)?;
        Ok(RenderOutput {
            image,
            plan: ScenePlan {
                clusters: (0..model.clusters()).collect(),
                texture_size: model.width(),
            },
            tile: model.width(),
            subspaces_total: 0,
            subspaces_synthesized: 0,
            texels_synthesized: 0,
            synthesis_seconds: 0.0,
            render_seconds: start.elapsed().as_secs_f64(),
            adapter: self.ctx.describe(),
        })
    }

    /// Renders one frame whose uniforms are written already: clears, `draw`s, reads back.
    fn render_frame(
        &self,
        scene: &Scene,
        draw: impl FnOnce(&mut wgpu::RenderPass<'_>),
    ) -> Result<Array3<f32>> {
        let device = &self.ctx.device;
        let (w, h) = (scene.width, scene.height);
        let extent = wgpu::Extent3d {
            width: w,
            height: h,
            depth_or_array_layers: 1,
        };
        let target = |format, usage| {
            device.create_texture(&wgpu::TextureDescriptor {
                label: Some("target"),
                size: extent,
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format,
                usage,
                view_formats: &[],
            })
        };
        let colour = self.ctx.checked("render target", || {
            target(
                TARGET_FORMAT,
                wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
            )
        })?;
        let depth = target(DEPTH_FORMAT, wgpu::TextureUsages::RENDER_ATTACHMENT);
        let colour_view = colour.create_view(&Default::default());
        let depth_view = depth.create_view(&Default::default());
        let mut encoder = device.create_command_encoder(&Default::default());
        encode_frame(&mut encoder, &colour_view, &depth_view, draw);
        self.ctx.queue.submit([encoder.finish()]);
        let data = read_texture(&self.ctx, &colour, 16)?;
        let row_bytes = w as usize * 16;
        let mut image = Array3::<f32>::zeros((3, h as usize, w as usize));
        for y in 0..h as usize {
            let row = &data[y * row_bytes..(y + 1) * row_bytes];
            for x in 0..w as usize {
                for c in 0..3 {
                    let at = 16 * x + 4 * c;
                    image[[c, y, x]] =
                        f32::from_le_bytes([row[at], row[at + 1], row[at + 2], row[at + 3]]);
                }
            }
        }
        Ok(image)
    }

    /// The whole job: plans the scene, synthesizes exactly the subspace images it needs
    /// (tileable, at the tile's side), uploads them at the planned resolution and renders
    /// one frame.
    ///
    /// # Errors
    /// An invalid size, a synthesis error or a device error.
    pub fn render_model(
        &self,
        model: &MaterialModel,
        mesh: &Mesh,
        scene: &Scene,
        options: &ModelRenderOptions,
    ) -> Result<RenderOutput> {
        check_size(scene.width, scene.height)?;
        if options.mapping == Mapping::Lpca {
            return Err(RenderError::Unsupported(
                "--mapping lpca renders .lpca models only; an MRF model (.btfm) renders with \
                 bump, displacement or plain"
                    .into(),
            ));
        }
        let start = Instant::now();
        let luts = (
            DirectionLut::new(model.views())?,
            DirectionLut::new(model.lights())?,
        );
        let min_side = model.min_synthesis_side().max(32);
        let tile = options.tile;
        if !tile.is_power_of_two() || !(min_side..=MAX_RENDER_SIDE as usize).contains(&tile) {
            return Err(RenderError::parameter(
                "--tile",
                format!("{tile} is not a power of two within {min_side}..={MAX_RENDER_SIDE}"),
            ));
        }
        // The footprint picks how finely the tile is sampled, never more finely than the
        // tile's own texels.
        let mut plan = plan_scene(
            model,
            mesh,
            scene,
            (&luts.0, &luts.1),
            (
                MIN_TEXTURE_SIDE.min(tile),
                options.max_texture_size.min(tile),
            ),
        );
        if let Some(side) = options.texture_size {
            if side == 0 || !side.is_power_of_two() || side > MAX_RENDER_SIDE as usize {
                return Err(RenderError::parameter(
                    "--texture-size",
                    format!("{side} is not a power of two within 1..={MAX_RENDER_SIDE}"),
                ));
            }
            plan.texture_size = side.min(tile);
        }
        let synthesis = SynthesisOptions {
            rows: tile,
            cols: tile,
            seed: options.seed,
            tileable: true,
        };
        let cache = model.synthesis_cache_for(&plan.clusters, &synthesis)?;
        let synthesized = plan.clusters.len();
        self.finish(
            model,
            &cache,
            luts,
            plan,
            synthesized,
            mesh,
            scene,
            options.mapping,
            start,
        )
    }

    /// As [`Renderer::render_model`], drawing on (and adding to) `cache`, whose size, seed and
    /// tileability are used as they are (`cache` must be tileable to wrap seamlessly): for
    /// many frames of one material, each subspace image is synthesized once. The plan's
    /// clusters that `cache` lacks are synthesized; the output counts only those.
    ///
    /// # Errors
    /// An invalid size, a synthesis error or a device error.
    pub fn render_cached(
        &self,
        model: &MaterialModel,
        cache: &SynthesisCache,
        mesh: &Mesh,
        scene: &Scene,
        mapping: Mapping,
    ) -> Result<RenderOutput> {
        check_size(scene.width, scene.height)?;
        let start = Instant::now();
        let luts = (
            DirectionLut::new(model.views())?,
            DirectionLut::new(model.lights())?,
        );
        let size = cache.options().rows;
        if cache.options().cols != size {
            return Err(RenderError::parameter(
                "cache",
                format!("{}x{size} is not square", cache.options().cols),
            ));
        }
        let mut plan = plan_scene(model, mesh, scene, (&luts.0, &luts.1), (size, size));
        plan.texture_size = size;
        let missing: Vec<usize> = plan
            .clusters
            .iter()
            .copied()
            .filter(|&k| cache.get(k).is_none())
            .collect();
        missing
            .par_iter()
            .try_for_each(|&k| model.subspace_from_cache(cache, k).map(|_| ()))?;
        self.finish(
            model,
            cache,
            luts,
            plan,
            missing.len(),
            mesh,
            scene,
            mapping,
            start,
        )
    }

    /// Uploads what `cache` holds and renders the frame.
    #[allow(clippy::too_many_arguments)]
    fn finish(
        &self,
        model: &MaterialModel,
        cache: &SynthesisCache,
        luts: (DirectionLut, DirectionLut),
        plan: ScenePlan,
        synthesized: usize,
        mesh: &Mesh,
        scene: &Scene,
        mapping: Mapping,
        start: Instant,
    ) -> Result<RenderOutput> {
        let (rows, cols) = (cache.options().rows, cache.options().cols);
        let heights = match mapping {
            Mapping::Displacement => model.range_heights(rows, cols, cache.options().seed),
            _ => None,
        };
        let tables =
            MaterialTables::new(model, cache, Some(luts))?.at_resolution(plan.texture_size)?;
        let synthesis_seconds = start.elapsed().as_secs_f64();
        let start = Instant::now();
        let material =
            GpuMaterial::new(&self.ctx, &self.pipelines, cache, heights.as_ref(), &tables)?;
        let gpu_mesh = GpuMesh::new(&self.ctx, mesh);
        let image = self.render(&material, &gpu_mesh, scene, mapping)?;
        let render_seconds = start.elapsed().as_secs_f64();
        Ok(RenderOutput {
            image,
            subspaces_synthesized: synthesized,
            texels_synthesized: (synthesized * rows * cols) as u64,
            plan,
            tile: rows,
            subspaces_total: model.subspaces().len(),
            synthesis_seconds,
            render_seconds,
            adapter: self.ctx.describe(),
        })
    }
}
