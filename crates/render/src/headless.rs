//! Offscreen rendering to linear RGB images, and the whole "model -> picture" job per
//! [`Material`]: what each costs is reported per material ([`MrfStats`], [`LpcaStats`]).

use std::time::Instant;

use ndarray::Array3;

use super::frame::{TARGET_FORMAT, check_size, render_offscreen};
use super::lpca::{GpuLpca, LpcaPass};
use super::lut::DirectionLut;
use super::mesh::Mesh;
use super::mrf::{GpuMaterial, MaterialTables, MrfPass};
use super::pipeline::GpuMesh;
use super::plan::{ScenePlan, plan_scene};
use super::scene::Scene;
use super::{GpuContext, Mapping, Material, RenderError, Result, check_tile};
use btfmrf::lpca::{LpcaModel, Method};
use btfmrf::model::MaterialModel;
use btfmrf::progress::{NoProgress, Progress};
use btfmrf::synthesis::{SynthesisCache, SynthesisOptions};
use rayon::prelude::*;

/// The coarsest texture side the footprint may choose, texels.
const MIN_TEXTURE_SIDE: usize = 16;

/// A device and each material's pass for offscreen targets ([`TARGET_FORMAT`]).
#[derive(Debug)]
pub struct Renderer {
    /// The device.
    pub ctx: GpuContext,
    /// The MRF pass (one pipeline per [`Mapping`]).
    pub mrf: MrfPass,
    /// The LPCA pass.
    pub lpca: LpcaPass,
}

/// A rendered picture and what it cost; `S` is the material's own account.
#[derive(Debug, Clone)]
pub struct RenderOutput<S = RenderStats> {
    /// Linear RGB, planar (3, height, width).
    pub image: Array3<f32>,
    /// What the material did for this frame.
    pub stats: S,
    /// Seconds spent uploading, rendering and reading back the frame.
    pub render_seconds: f64,
    /// The adapter, e.g. "llvmpipe (LLVM 15.0.6, 256 bits) (Vulkan)".
    pub adapter: String,
}

impl<S> RenderOutput<S> {
    fn map_stats<T>(self, f: impl FnOnce(S) -> T) -> RenderOutput<T> {
        RenderOutput {
            image: self.image,
            stats: f(self.stats),
            render_seconds: self.render_seconds,
            adapter: self.adapter,
        }
    }
}

/// What an MRF frame synthesized.
#[derive(Debug, Clone)]
pub struct MrfStats {
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
    /// Seconds spent synthesizing subspace images and range map, and finishing pairs.
    pub synthesis_seconds: f64,
}

/// What an LPCA frame decoded from (nothing is synthesized).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LpcaStats {
    /// LPCA or PCA RF.
    pub method: Method,
    /// Clusters of the model (PCA RF: one per view).
    pub clusters: usize,
    /// The measured tile that repeats on the mesh, texels (width, height).
    pub size: (usize, usize),
}

/// The account of a frame of either material ([`Renderer::render_material`]).
#[derive(Debug, Clone)]
pub enum RenderStats {
    /// See [`MrfStats`].
    Mrf(MrfStats),
    /// See [`LpcaStats`].
    Lpca(LpcaStats),
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

/// One MRF frame to draw, with its direction tables and the time its job started.
struct MrfJob<'a> {
    model: &'a MaterialModel,
    mesh: &'a Mesh,
    scene: &'a Scene,
    mapping: Mapping,
    luts: (DirectionLut, DirectionLut),
    start: Instant,
}

impl<'a> MrfJob<'a> {
    fn new(
        model: &'a MaterialModel,
        mesh: &'a Mesh,
        scene: &'a Scene,
        mapping: Mapping,
    ) -> Result<Self> {
        check_size(scene.width, scene.height)?;
        let start = Instant::now();
        Ok(Self {
            model,
            mesh,
            scene,
            mapping,
            luts: (
                DirectionLut::new(model.views())?,
                DirectionLut::new(model.lights())?,
            ),
            start,
        })
    }

    /// The scene's plan; plain texturing shows one subspace image as it is, so it finishes
    /// no pair.
    fn plan(&self, sizes: (usize, usize)) -> ScenePlan {
        let mut plan = plan_scene(
            self.model,
            self.mesh,
            self.scene,
            (&self.luts.0, &self.luts.1),
            sizes,
        );
        if self.mapping == Mapping::Plain {
            plan.finishes.clear();
        }
        plan
    }
}

impl Renderer {
    /// A headless device and every material's pass.
    ///
    /// # Errors
    /// No adapter, or a device or shader error.
    pub fn new() -> Result<Self> {
        let ctx = GpuContext::headless()?;
        let mrf = MrfPass::new(&ctx, TARGET_FORMAT)?;
        let lpca = LpcaPass::new(&ctx, TARGET_FORMAT)?;
        Ok(Self { ctx, mrf, lpca })
    }

    /// Renders `mesh` with an MRF `material` by `mapping` to a linear RGB image (black
    /// background).
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
        check_size(scene.width, scene.height)?;
        material.set_frame(&self.ctx, scene, mesh);
        render_offscreen(&self.ctx, (scene.width, scene.height), |pass| {
            self.mrf.draw(pass, mapping, material, mesh)
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
        model.set_frame(&self.ctx, scene);
        render_offscreen(&self.ctx, (scene.width, scene.height), |pass| {
            self.lpca.draw(pass, model, mesh)
        })
    }

    /// The whole job for either material: [`Renderer::render_model`] or
    /// [`Renderer::render_lpca`]; `progress` counts an MRF model's subspace images as they
    /// are synthesized, then its pairs as they are finished.
    ///
    /// # Errors
    /// As theirs.
    pub fn render_material(
        &self,
        material: Material<'_>,
        mesh: &Mesh,
        scene: &Scene,
        progress: &dyn Progress,
    ) -> Result<RenderOutput> {
        Ok(match material {
            Material::Mrf(model, options) => self
                .render_model_counted(model, mesh, scene, &options, progress)?
                .map_stats(RenderStats::Mrf),
            Material::Lpca(model) => self
                .render_lpca(model, mesh, scene)?
                .map_stats(RenderStats::Lpca),
        })
    }

    /// The whole LPCA job: uploads `model` (cluster indices, weights, eigen-ABRDFs and the
    /// direction tables) and renders one frame, every fragment decoding its texel. Nothing is
    /// synthesized.
    ///
    /// # Errors
    /// An invalid size, a PCA BTF model, a model beyond the device's limits or a device error.
    pub fn render_lpca(
        &self,
        model: &LpcaModel,
        mesh: &Mesh,
        scene: &Scene,
    ) -> Result<RenderOutput<LpcaStats>> {
        check_size(scene.width, scene.height)?;
        let start = Instant::now();
        let luts = (
            DirectionLut::new(model.views())?,
            DirectionLut::new(model.lights())?,
        );
        let gpu = GpuLpca::new(&self.ctx, &self.lpca, model, (&luts.0, &luts.1))?;
        let gpu_mesh = GpuMesh::new(&self.ctx, mesh);
        let image = self.render_gpu_lpca(&gpu, &gpu_mesh, scene)?;
        Ok(RenderOutput {
            image,
            stats: LpcaStats {
                method: model.method(),
                clusters: model.clusters(),
                size: (model.width(), model.height()),
            },
            render_seconds: start.elapsed().as_secs_f64(),
            adapter: self.ctx.describe(),
        })
    }

    /// The whole MRF job: plans the scene, synthesizes exactly the subspace images it needs
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
    ) -> Result<RenderOutput<MrfStats>> {
        self.render_model_counted(model, mesh, scene, options, &NoProgress)
    }

    /// [`Renderer::render_model`] with its synthesis and finishes counted by `progress`.
    fn render_model_counted(
        &self,
        model: &MaterialModel,
        mesh: &Mesh,
        scene: &Scene,
        options: &ModelRenderOptions,
        progress: &dyn Progress,
    ) -> Result<RenderOutput<MrfStats>> {
        let job = MrfJob::new(model, mesh, scene, options.mapping)?;
        let tile = options.tile;
        check_tile(model, tile)?;
        // The footprint picks how finely the tile is sampled, never more finely than the
        // tile's own texels.
        let mut plan = job.plan((
            MIN_TEXTURE_SIDE.min(tile),
            options.max_texture_size.min(tile),
        ));
        if let Some(side) = options.texture_size {
            if side == 0 || !side.is_power_of_two() || side > super::MAX_RENDER_SIDE as usize {
                return Err(RenderError::parameter(
                    "--texture-size",
                    format!(
                        "{side} is not a power of two within 1..={}",
                        super::MAX_RENDER_SIDE
                    ),
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
        let cache = model.synthesis_cache_for(&plan.clusters, &synthesis, progress)?;
        let synthesized = plan.clusters.len();
        self.finish(job, &cache, plan, synthesized, progress)
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
    ) -> Result<RenderOutput<MrfStats>> {
        let job = MrfJob::new(model, mesh, scene, mapping)?;
        let size = cache.options().rows;
        if cache.options().cols != size {
            return Err(RenderError::parameter(
                "cache",
                format!("{}x{size} is not square", cache.options().cols),
            ));
        }
        let mut plan = job.plan((size, size));
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
        self.finish(job, cache, plan, missing.len(), &NoProgress)
    }

    /// Uploads what `cache` holds (`synthesized` of its subspace images new for this frame)
    /// and the plan's finishes (counted by `progress`), and renders `job`'s frame.
    fn finish(
        &self,
        job: MrfJob<'_>,
        cache: &SynthesisCache,
        plan: ScenePlan,
        synthesized: usize,
        progress: &dyn Progress,
    ) -> Result<RenderOutput<MrfStats>> {
        let (rows, cols) = (cache.options().rows, cache.options().cols);
        let model = job.model;
        let tables = MaterialTables::new(model, cache, Some(job.luts), &plan.finishes, progress)?
            .at_resolution(plan.texture_size)?;
        let synthesis_seconds = job.start.elapsed().as_secs_f64();
        let start = Instant::now();
        let material = GpuMaterial::new(&self.ctx, &self.mrf, cache, &tables)?;
        let gpu_mesh = GpuMesh::new(&self.ctx, job.mesh);
        let image = self.render(&material, &gpu_mesh, job.scene, job.mapping)?;
        Ok(RenderOutput {
            image,
            stats: MrfStats {
                subspaces_synthesized: synthesized,
                texels_synthesized: (synthesized * rows * cols) as u64,
                plan,
                tile: rows,
                subspaces_total: model.subspaces().len(),
                synthesis_seconds,
            },
            render_seconds: start.elapsed().as_secs_f64(),
            adapter: self.ctx.describe(),
        })
    }
}
