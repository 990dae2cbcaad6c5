//! The MRF material on the GPU: synthesized subspace images in a texture array, the range map
//! as a relief texture, the cluster of every measured (view, light) pair, and the pass that
//! draws them with one pipeline per [`Mapping`] (`shaders/mrf.wgsl` and the mapping's file).

use half::f16;
use ndarray::{Array2, Array3};
use rayon::prelude::*;
use wgpu::util::DeviceExt;

use super::lut::{DirectionLut, MeanShading};
use super::pipeline::{
    COMMON_WGSL, CommonBuffers, GpuMesh, bind_group_layout, common_layout_entries, render_pipeline,
    storage_buffer, storage_entry,
};
use super::scene::Scene;
use super::{GpuContext, Mapping, RenderError, Result};
use btfmrf::geometry::relight::Shadows;
use btfmrf::model::MaterialModel;
use btfmrf::progress::Progress;
use btfmrf::synthesis::{Finish, SynthesisCache};

const MRF_WGSL: &str = include_str!("../../../shaders/mrf.wgsl");

/// The WGSL source of a mapping's pipeline: `common.wgsl`, the CPU's shading floor
/// (`SHADING_FLOOR`, [`btfmrf::geometry::relight::SHADING_FLOOR`]), whether the relief's view
/// parallax is marched (`VIEW_PARALLAX`: bump mapping; displaced geometry shows its own),
/// `mrf.wgsl`, then the mapping's own file.
pub fn shader_source(mapping: Mapping) -> String {
    let own = match mapping {
        Mapping::Bump => include_str!("../../../shaders/bump.wgsl"),
        Mapping::Displacement => include_str!("../../../shaders/displacement.wgsl"),
        Mapping::Plain => include_str!("../../../shaders/plain.wgsl"),
    };
    let floor = btfmrf::geometry::relight::SHADING_FLOOR;
    let parallax = mapping == Mapping::Bump;
    format!(
        "{COMMON_WGSL}\nconst SHADING_FLOOR: f32 = {floor:?};\nconst VIEW_PARALLAX: bool = {parallax};\n{MRF_WGSL}\n{own}"
    )
}

/// The CPU side of a material on the GPU: what [`GpuMaterial::new`] uploads.
#[derive(Debug, Clone)]
pub struct MaterialTables {
    /// Texture side on the GPU, texels: the synthesized tile ([`MaterialTables::tile`])
    /// box-filtered down by a power of two (the screen footprint asks for no more).
    pub size: usize,
    /// Side of the synthesized tile, measured texels: what one texture repetition holds on
    /// the mesh, whatever [`MaterialTables::size`] samples it at.
    pub tile: usize,
    /// Clusters with a texture layer, in layer order.
    pub clusters: Vec<usize>,
    /// Per (view * lights + light), the texture layer of its cluster or `u32::MAX`.
    pub pair_layer: Vec<u32>,
    /// Per (view * lights + light), the pair's gain ([`MaterialModel::pair_gain`]).
    pub pair_gain: Vec<f32>,
    /// The measured (view, light) pairs with parts of their own that the scene draws on and
    /// their finishes ([`MaterialModel::pair_finish`]: light tables, a light's own detail), in
    /// layer order.
    pub finishes: Vec<((usize, usize), Finish)>,
    /// Measured views and lights.
    pub counts: (usize, usize),
    /// Direction tables of the views and of the lights.
    pub view_lut: DirectionLut,
    /// See `view_lut`.
    pub light_lut: DirectionLut,
    /// Mean shading of the range map's normals (`None` without a range map), with its cast
    /// shadows where the map casts them.
    pub mean_shading: Option<MeanShading>,
    /// The range map's heights as the shader's rays need them; `None` without a range map.
    pub relief_heights: Option<ReliefHeights>,
    /// Per measured light, the bump strength `k` of the shading factor `1 + k (s - 1)`
    /// ([`btfmrf::geometry::relight`]; 1 where the model stores none).
    pub light_strength: Vec<f32>,
}

/// The span of a range map's heights for the shader's rays (view parallax, cast shadows).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReliefHeights {
    /// The highest height above the mean, tile texels (rays are free above it).
    pub top: f32,
    /// The lowest height, below the mean (negative), tile texels.
    pub bottom: f32,
    /// Whether the range map casts shadows.
    pub casts_shadows: bool,
}

impl MaterialTables {
    /// The tables for `model` with the clusters synthesized in `cache` and the finishes of
    /// the measured `pairs` (made here where `cache` lacks them, counted by `progress` as
    /// task "finishing pairs"; pairs without parts of their own are skipped); `luts` are the
    /// model's view and light tables, when already built (else they are built here).
    ///
    /// # Errors
    /// A pair out of range, or a synthesis error while making a finish.
    pub fn new(
        model: &MaterialModel,
        cache: &SynthesisCache,
        luts: Option<(DirectionLut, DirectionLut)>,
        pairs: &[(usize, usize)],
        progress: &dyn Progress,
    ) -> Result<Self> {
        let (view_lut, light_lut) = match luts {
            Some(l) => l,
            None => (
                DirectionLut::new(model.views())?,
                DirectionLut::new(model.lights())?,
            ),
        };
        let clusters: Vec<usize> = (0..model.subspaces().len())
            .filter(|&k| cache.get(k).is_some())
            .collect();
        let mut layer_of = vec![u32::MAX; model.subspaces().len()];
        for (layer, &k) in clusters.iter().enumerate() {
            layer_of[k] = layer as u32;
        }
        let (nv, nl) = (model.views().len(), model.lights().len());
        // The zenith angle of the set's lowest light, degrees.
        let lowest = model.lights().lowest_theta();
        let casts_shadows = model
            .range_map()
            .is_some_and(|m| m.shadows == Shadows::Cast);
        // The heights whose shadows the shader casts.
        let cast = cache.heights().filter(|_| casts_shadows);
        // The cluster table is view-major, like the pair layers.
        let pair_layer = model
            .cluster_table()
            .iter()
            .map(|&c| layer_of[usize::from(c)])
            .collect();
        let pair_gain = (0..nv * nl)
            .map(|i| model.pair_gain(i / nl, i % nl) as f32)
            .collect();
        progress.start("finishing pairs", pairs.len() as u64);
        let finishes = pairs
            .par_iter()
            .filter_map(|&(v, l)| {
                let finish = model.pair_finish(cache, v, l).transpose();
                progress.advance(1);
                Some(finish?.map(|f| ((v, l), f)))
            })
            .collect::<std::result::Result<_, _>>();
        progress.finish();
        let finishes = finishes?;
        Ok(Self {
            finishes,
            size: cache.options().rows,
            tile: cache.options().rows,
            clusters,
            pair_layer,
            pair_gain,
            counts: (nv, nl),
            view_lut,
            light_lut,
            mean_shading: cache.normals().map(|n| match cast {
                Some(h) => MeanShading::with_cast_shadows(n, h, lowest),
                None => MeanShading::new(n),
            }),
            relief_heights: cache.heights().map(|h| {
                let mean = h.mean().unwrap_or(0.0);
                let (top, bottom) = btfmrf::geometry::parallax::height_span(h);
                ReliefHeights {
                    top: (top - mean) as f32,
                    bottom: (bottom - mean) as f32,
                    casts_shadows,
                }
            }),
            light_strength: (0..nl)
                .map(|l| model.range_map().map_or(1.0, |m| m.strength_of(l)) as f32)
                .collect(),
        })
    }

    /// The same tables with the tile sampled at `side` texels on the GPU (a power-of-two
    /// fraction of the tile, at least 1).
    ///
    /// # Errors
    /// A `side` that is not the tile divided by a power of two.
    pub fn at_resolution(mut self, side: usize) -> Result<Self> {
        if side == 0
            || side > self.tile
            || !(self.tile / side).is_power_of_two()
            || !self.tile.is_multiple_of(side)
        {
            return Err(RenderError::parameter(
                "--texture-size",
                format!(
                    "{side} is not the {}-texel tile divided by a power of two",
                    self.tile
                ),
            ));
        }
        self.size = side;
        Ok(self)
    }
}

/// A material's textures, tables and uniforms on the GPU, bound as group 0 of [`MrfPass`].
#[derive(Debug)]
pub struct GpuMaterial {
    common: CommonBuffers,
    bind_group: wgpu::BindGroup,
    /// Texture side on the GPU, texels.
    pub size: usize,
    /// Side of the synthesized tile, measured texels (the unit of the range map's heights).
    pub tile: usize,
    /// True when the model has a range map.
    pub has_relief: bool,
    /// See [`MaterialTables::relief_heights`].
    pub relief_heights: Option<ReliefHeights>,
}

/// The mean-centred heights (tile texels) for the shader's rays, row-major, at the tile's full
/// resolution whatever the other textures' (box-filtered heights hid less from an oblique
/// view: a 128-texel texture's render of a 256-texel tile drifted from the 256-texel one).
fn ray_heights(heights: &Array2<f64>) -> Vec<f32> {
    let mean = heights.mean().unwrap_or(0.0);
    heights.iter().map(|&h| (h - mean) as f32).collect()
}

/// Mip levels of a `side` x `side` texture (down to 1 x 1).
pub fn mip_levels(side: usize) -> u32 {
    usize::BITS - side.max(1).leading_zeros()
}

/// One layer's texels and its mip chain (2 x 2 box filter; odd sides clamp), as RGBA f16
/// bytes, finest level first, appended to `out`; the first `skip` levels are made but not
/// written (the texture then starts at side `side >> skip`, the same surface coarser).
fn push_mip_chain(
    out: &mut Vec<u8>,
    side: usize,
    skip: u32,
    texel: impl Fn(usize, usize) -> [f32; 4],
) {
    let mut level: Vec<[f32; 4]> = (0..side * side)
        .map(|i| texel(i / side, i % side))
        .collect();
    let mut n = side;
    for l in 0..mip_levels(side) {
        if l > 0 {
            let m = (n / 2).max(1);
            let at = |y: usize, x: usize| level[y.min(n - 1) * n + x.min(n - 1)];
            let next: Vec<[f32; 4]> = (0..m * m)
                .map(|i| {
                    let (y, x) = (2 * (i / m), 2 * (i % m));
                    let q = [at(y, x), at(y, x + 1), at(y + 1, x), at(y + 1, x + 1)];
                    std::array::from_fn(|c| 0.25 * (q[0][c] + q[1][c] + q[2][c] + q[3][c]))
                })
                .collect();
            level = next;
            n = m;
        }
        if l < skip {
            continue;
        }
        for t in &level {
            for v in t {
                out.extend_from_slice(&f16::from_f32(*v).to_le_bytes());
            }
        }
    }
}

impl GpuMaterial {
    /// Uploads the synthesized subspace images of `cache`, its range map (normals, and
    /// heights mean-centred here for displacement and cast shadows) and the tables, for
    /// `pass`.
    ///
    /// # Errors
    /// A texture beyond the device's limits.
    pub fn new(
        ctx: &GpuContext,
        pass: &MrfPass,
        cache: &SynthesisCache,
        tables: &MaterialTables,
    ) -> Result<Self> {
        let heights = cache.heights();
        let device = &ctx.device;
        let size = tables.size;
        let limits = device.limits();
        if size as u32 > limits.max_texture_dimension_2d {
            return Err(RenderError::parameter(
                "--texture-size",
                format!(
                    "{size} exceeds the device's {} texels",
                    limits.max_texture_dimension_2d
                ),
            ));
        }
        // A layer of zeros stands in when nothing was synthesized (the plain pipeline samples
        // layer 0; the bump and displacement pipelines skip missing layers).
        let tile = tables.tile;
        let skip = (tile / size.max(1)).trailing_zeros();
        let zero = Array3::<f32>::zeros((3, tile, tile));
        let mut planes: Vec<&Array3<f32>> = tables
            .clusters
            .iter()
            .filter_map(|&k| cache.get(k))
            .collect();
        if planes.is_empty() {
            planes.push(&zero);
        }
        // A square texture of `side` texels and `layers` layers, with `mips` levels in `data`.
        let upload = |label, side: usize, layers: usize, format, mips, data: &[u8]| {
            device.create_texture_with_data(
                &ctx.queue,
                &wgpu::TextureDescriptor {
                    label: Some(label),
                    size: wgpu::Extent3d {
                        width: side as u32,
                        height: side as u32,
                        depth_or_array_layers: layers as u32,
                    },
                    mip_level_count: mips,
                    sample_count: 1,
                    dimension: wgpu::TextureDimension::D2,
                    format,
                    usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
                    view_formats: &[],
                },
                wgpu::util::TextureDataOrder::LayerMajor,
                data,
            )
        };
        // The half-float RGBA textures, with their whole mip chain.
        let texture = |label, layers: usize, data: &[u8]| {
            upload(
                label,
                size,
                layers,
                wgpu::TextureFormat::Rgba16Float,
                mip_levels(size),
                data,
            )
        };
        let mut sub_data = Vec::new();
        for p in &planes {
            push_mip_chain(&mut sub_data, tile, skip, |y, x| {
                [p[[0, y, x]], p[[1, y, x]], p[[2, y, x]], 1.0]
            });
        }
        let subspaces = ctx.checked("subspace textures", || {
            texture("subspaces", planes.len(), &sub_data)
        })?;
        let has_relief = cache.normals().is_some();
        // Mip levels average the normals without renormalising them: far away, the shading
        // max(0, n . l) then tends to the mean over the footprint, as it should.
        let mut relief_data = Vec::new();
        match cache.normals() {
            Some(n) => {
                let mean = heights.map_or(0.0, |h| h.mean().unwrap_or(0.0));
                push_mip_chain(&mut relief_data, tile, skip, |y, x| {
                    let h = heights.map_or(0.0, |h| h[[y, x]] - mean);
                    [n[[0, y, x]], n[[1, y, x]], n[[2, y, x]], h].map(|v| v as f32)
                });
            }
            None => push_mip_chain(&mut relief_data, tile, skip, |_, _| [0.0, 0.0, 1.0, 0.0]),
        }
        let relief = ctx.checked("relief texture", || texture("relief", 1, &relief_data))?;
        // The pairs' finishes; one texel of zeros stands in when there are none.
        let finishes = if tables.finishes.is_empty() {
            let zeros = [0u8; 8];
            ctx.checked("pair finishes", || {
                upload(
                    "pair finishes",
                    1,
                    1,
                    wgpu::TextureFormat::Rgba16Float,
                    1,
                    &zeros,
                )
            })?
        } else {
            let mut data = Vec::new();
            for (_, f) in &tables.finishes {
                push_mip_chain(&mut data, tile, skip, |y, x| {
                    [f[[0, y, x]], f[[1, y, x]], f[[2, y, x]], 0.0]
                });
            }
            ctx.checked("pair finishes", || {
                texture("pair finishes", tables.finishes.len(), &data)
            })?
        };
        let (ray_side, ray_data) = match heights {
            Some(h) => (tile, ray_heights(h)),
            None => (1, vec![0.0]),
        };
        let rays = ctx.checked("ray heights", || {
            let bytes = bytemuck::cast_slice(&ray_data);
            upload(
                "ray heights",
                ray_side,
                1,
                wgpu::TextureFormat::R32Float,
                1,
                bytes,
            )
        })?;
        let common = CommonBuffers::new(ctx, (&tables.view_lut, &tables.light_lut))?;
        // Per pair, its cluster's layer and its finish's, as `pair_layer`'s x and y.
        let nl = tables.counts.1;
        let mut layers: Vec<u32> = (tables.pair_layer.iter())
            .flat_map(|&c| [c, u32::MAX])
            .collect();
        for (layer, &((v, l), _)) in tables.finishes.iter().enumerate() {
            layers[2 * (v * nl + l) + 1] = layer as u32;
        }
        let pair_layer = storage_buffer(ctx, "pair layers", bytemuck::cast_slice(&layers))?;
        // Per pair, its gain and its mean colour (the gain times its cluster's tile mean, plus
        // its finish's mean): what the shader blends to turn the brightness across a cut.
        let channel_means = |image: &Array3<f32>| {
            [0, 1, 2].map(|c| image.index_axis(ndarray::Axis(0), c).mean().unwrap_or(0.0))
        };
        let layer_means: Vec<[f32; 3]> = planes.iter().map(|p| channel_means(p)).collect();
        let mut pair_shade: Vec<[f32; 4]> = (tables.pair_layer.iter().zip(&tables.pair_gain))
            .map(|(&layer, &gain)| {
                let [r, g, b] = layer_means
                    .get(layer as usize)
                    .map_or([0.0; 3], |m| m.map(|x| gain * x));
                [gain, r, g, b]
            })
            .collect();
        for ((v, l), f) in &tables.finishes {
            let shade = &mut pair_shade[v * nl + l];
            for (c, m) in channel_means(f).into_iter().enumerate() {
                shade[c + 1] += m;
            }
        }
        let pair_shade = storage_buffer(
            ctx,
            "pair gains and means",
            bytemuck::cast_slice(&pair_shade),
        )?;
        let ones = vec![1.0f32; super::lut::SHADING_GRID * super::lut::SHADING_GRID];
        let shading = tables.mean_shading.as_ref().map_or(&ones, |m| &m.values);
        let mean_shade = storage_buffer(ctx, "mean shading", bytemuck::cast_slice(shading))?;
        let light_strength = storage_buffer(
            ctx,
            "light strengths",
            bytemuck::cast_slice(&tables.light_strength),
        )?;
        let sampler = device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("repeat"),
            address_mode_u: wgpu::AddressMode::Repeat,
            address_mode_v: wgpu::AddressMode::Repeat,
            mag_filter: wgpu::FilterMode::Linear,
            min_filter: wgpu::FilterMode::Linear,
            mipmap_filter: wgpu::MipmapFilterMode::Linear,
            ..Default::default()
        });
        let sub_view = subspaces.create_view(&wgpu::TextureViewDescriptor {
            dimension: Some(wgpu::TextureViewDimension::D2Array),
            ..Default::default()
        });
        let relief_view = relief.create_view(&wgpu::TextureViewDescriptor::default());
        let ray_view = rays.create_view(&wgpu::TextureViewDescriptor::default());
        let finish_view = finishes.create_view(&wgpu::TextureViewDescriptor {
            dimension: Some(wgpu::TextureViewDimension::D2Array),
            ..Default::default()
        });
        let mut entries = common.entries();
        entries.extend([
            wgpu::BindGroupEntry {
                binding: 1,
                resource: wgpu::BindingResource::TextureView(&sub_view),
            },
            wgpu::BindGroupEntry {
                binding: 2,
                resource: wgpu::BindingResource::TextureView(&relief_view),
            },
            wgpu::BindGroupEntry {
                binding: 3,
                resource: wgpu::BindingResource::Sampler(&sampler),
            },
            wgpu::BindGroupEntry {
                binding: 8,
                resource: pair_layer.as_entire_binding(),
            },
            wgpu::BindGroupEntry {
                binding: 9,
                resource: mean_shade.as_entire_binding(),
            },
            wgpu::BindGroupEntry {
                binding: 10,
                resource: light_strength.as_entire_binding(),
            },
            wgpu::BindGroupEntry {
                binding: 12,
                resource: wgpu::BindingResource::TextureView(&ray_view),
            },
            wgpu::BindGroupEntry {
                binding: 11,
                resource: pair_shade.as_entire_binding(),
            },
            wgpu::BindGroupEntry {
                binding: 13,
                resource: wgpu::BindingResource::TextureView(&finish_view),
            },
        ]);
        let bind_group = ctx.checked("material bind group", || {
            device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("material"),
                layout: &pass.layout,
                entries: &entries,
            })
        })?;
        Ok(Self {
            common,
            bind_group,
            size,
            tile,
            has_relief,
            relief_heights: tables.relief_heights,
        })
    }

    /// Writes the uniforms of one frame of `scene` on `mesh` (whose texture scale sets the
    /// displacement's world units).
    pub fn set_frame(&self, ctx: &GpuContext, scene: &Scene, mesh: &GpuMesh) {
        let own = [
            if self.has_relief {
                self.tile as f32
            } else {
                0.0
            },
            mesh.world_per_uv / self.tile as f32,
            0.0,
        ];
        let relief = self.relief_heights.map_or([0.0; 4], |r| {
            [r.top, r.bottom, f32::from(u8::from(r.casts_shadows)), 0.0]
        });
        self.common.write(ctx, scene, (own, relief));
    }
}

/// The MRF material's bind group layout and one render pipeline per [`Mapping`], for one
/// colour format.
#[derive(Debug)]
pub struct MrfPass {
    layout: wgpu::BindGroupLayout,
    pipelines: [wgpu::RenderPipeline; 3],
}

impl MrfPass {
    /// Compiles the pipelines of every mapping for colour targets of `format`.
    ///
    /// # Errors
    /// A shader or pipeline the device rejects.
    pub fn new(ctx: &GpuContext, format: wgpu::TextureFormat) -> Result<Self> {
        let vf = wgpu::ShaderStages::VERTEX_FRAGMENT;
        let texture = |binding, dim| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: vf,
            ty: wgpu::BindingType::Texture {
                sample_type: wgpu::TextureSampleType::Float { filterable: true },
                view_dimension: dim,
                multisampled: false,
            },
            count: None,
        };
        let mut entries = common_layout_entries().to_vec();
        entries.extend([
            texture(1, wgpu::TextureViewDimension::D2Array),
            texture(2, wgpu::TextureViewDimension::D2),
            wgpu::BindGroupLayoutEntry {
                binding: 3,
                visibility: vf,
                ty: wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering),
                count: None,
            },
            storage_entry(8),
            storage_entry(9),
            storage_entry(10),
            storage_entry(11),
            wgpu::BindGroupLayoutEntry {
                binding: 12,
                visibility: wgpu::ShaderStages::FRAGMENT,
                ty: wgpu::BindingType::Texture {
                    sample_type: wgpu::TextureSampleType::Float { filterable: false },
                    view_dimension: wgpu::TextureViewDimension::D2,
                    multisampled: false,
                },
                count: None,
            },
            texture(13, wgpu::TextureViewDimension::D2Array),
        ]);
        let layout = bind_group_layout(ctx, "mrf material", &entries);
        let pipeline = |mapping: Mapping| {
            render_pipeline(ctx, mapping.name(), &layout, shader_source(mapping), format)
        };
        let [a, b, c] = Mapping::ALL;
        let pipelines = [pipeline(a)?, pipeline(b)?, pipeline(c)?];
        Ok(Self { layout, pipelines })
    }

    /// Records one draw of `mesh` with `material` by `mapping` into `pass`.
    pub fn draw(
        &self,
        pass: &mut wgpu::RenderPass<'_>,
        mapping: Mapping,
        material: &GpuMaterial,
        mesh: &GpuMesh,
    ) {
        mesh.draw(pass, &self.pipelines[mapping.index()], &material.bind_group);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn chain(side: usize, skip: u32) -> Vec<f32> {
        let mut bytes = Vec::new();
        push_mip_chain(&mut bytes, side, skip, |y, x| {
            [(y * side + x) as f32 / 64.0, y as f32, x as f32, 1.0]
        });
        bytes
            .chunks_exact(2)
            .map(|b| f16::from_le_bytes([b[0], b[1]]).to_f32())
            .collect()
    }

    #[test]
    fn a_coarser_texture_is_the_tail_of_the_full_mip_chain() {
        let full = chain(8, 0);
        // 8x8 + 4x4 + 2x2 + 1x1 texels of 4 channels.
        assert_eq!(full.len(), 4 * (64 + 16 + 4 + 1));
        let coarse = chain(8, 1);
        assert_eq!(coarse.len(), 4 * (16 + 4 + 1));
        assert_eq!(coarse[..], full[4 * 64..]);
        // The first coarse texel is the mean of the 2x2 block at the origin.
        assert_eq!(coarse[1], 0.5);
        assert_eq!(coarse[2], 0.5);
        assert_eq!(coarse[0], (0.0 + 1.0 + 8.0 + 9.0) / 4.0 / 64.0);
    }
}
