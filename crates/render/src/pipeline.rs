//! Shaders, the GPU resources of a material, and one render pipeline per [`Mapping`].
//!
//! Every pipeline shares one bind group layout (see `shaders/common.wgsl`): the uniforms, the
//! subspace-image texture array, the relief texture (normals + heights), a repeating sampler
//! and the lookup tables of [`super::lut`]. A new pipeline is a shader file plus one arm in
//! [`shader_source`] and [`Mapping`]; it may use its own bind group layout, as LPCA decoding
//! ([`Mapping::Lpca`], [`super::lpca`]) does: the uniforms and direction tables at the same
//! bindings, its model buffers at 10..13.

use std::collections::HashMap;

use half::f16;
use ndarray::{Array2, Array3};
use wgpu::util::DeviceExt;

use super::lut::{DirectionLut, MeanShading};
use super::mesh::{Mesh, Vertex};
use super::scene::Scene;
use super::{GpuContext, Mapping, RenderError, Result};
use btfmrf::model::MaterialModel;
use btfmrf::synthesis::SynthesisCache;

/// The depth buffer format of every pipeline.
pub const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

const COMMON: &str = include_str!("../../../shaders/common.wgsl");

/// The WGSL source of a pipeline: `common.wgsl` followed by the pipeline's own file.
pub fn shader_source(mapping: Mapping) -> String {
    let own = match mapping {
        Mapping::Bump => include_str!("../../../shaders/bump.wgsl"),
        Mapping::Displacement => include_str!("../../../shaders/displacement.wgsl"),
        Mapping::Plain => include_str!("../../../shaders/plain.wgsl"),
        Mapping::Lpca => include_str!("../../../shaders/lpca.wgsl"),
    };
    format!("{COMMON}\n{own}")
}

/// The shaders' `Globals` uniform block.
#[repr(C)]
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Globals {
    /// World to clip, column-major.
    pub view_proj: [[f32; 4]; 4],
    /// Camera position (w = 1) or direction (w = 0, orthographic).
    pub camera: [f32; 4],
    /// Light position (w = 1) or direction (w = 0).
    pub light: [f32; 4],
    /// Squared light distance, has-range-map flag, displacement scale, plain layer.
    pub params: [f32; 4],
    /// Measured views, measured lights.
    pub counts: [u32; 4],
}

/// A mesh uploaded to the GPU.
#[derive(Debug)]
pub struct GpuMesh {
    vertices: wgpu::Buffer,
    indices: wgpu::Buffer,
    count: u32,
    /// World units per texture repetition (scales the displacement).
    pub world_per_uv: f32,
}

impl GpuMesh {
    /// Uploads `mesh`.
    pub fn new(ctx: &GpuContext, mesh: &Mesh) -> Self {
        let vertices = ctx
            .device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("vertices"),
                contents: bytemuck::cast_slice(&mesh.vertices),
                usage: wgpu::BufferUsages::VERTEX,
            });
        let indices = ctx
            .device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("indices"),
                contents: bytemuck::cast_slice(&mesh.indices),
                usage: wgpu::BufferUsages::INDEX,
            });
        Self {
            vertices,
            indices,
            count: mesh.indices.len() as u32,
            world_per_uv: mesh.world_per_uv(),
        }
    }
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
    /// Measured views and lights.
    pub counts: (usize, usize),
    /// Direction tables of the views and of the lights.
    pub view_lut: DirectionLut,
    /// See `view_lut`.
    pub light_lut: DirectionLut,
    /// Mean shading of the range map's normals (`None` without a range map).
    pub mean_shading: Option<MeanShading>,
}

impl MaterialTables {
    /// The tables for `model` with the clusters synthesized in `cache`; `luts` are the
    /// model's view and light tables, when already built (else they are built here).
    ///
    /// # Errors
    /// Never for a valid model (direction interpolation of finite directions).
    pub fn new(
        model: &MaterialModel,
        cache: &SynthesisCache,
        luts: Option<(DirectionLut, DirectionLut)>,
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
        // The cluster table is view-major, like the pair layers.
        let pair_layer = model
            .cluster_table()
            .iter()
            .map(|&c| layer_of[usize::from(c)])
            .collect();
        Ok(Self {
            size: cache.options().rows,
            tile: cache.options().rows,
            clusters,
            pair_layer,
            counts: (nv, nl),
            view_lut,
            light_lut,
            mean_shading: cache.normals().map(MeanShading::new),
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

/// A material's textures, tables and uniforms on the GPU, bound as group 0.
#[derive(Debug)]
pub struct GpuMaterial {
    uniforms: wgpu::Buffer,
    bind_group: wgpu::BindGroup,
    /// Texture side on the GPU, texels.
    pub size: usize,
    /// Side of the synthesized tile, measured texels (the unit of the range map's heights).
    pub tile: usize,
    /// Measured views and lights.
    pub counts: (usize, usize),
    /// True when the model has a range map.
    pub has_relief: bool,
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
    /// Uploads the synthesized subspace images of `cache`, the range map (normals from the
    /// cache, `heights` for displacement, mean-centred here) and the tables.
    ///
    /// # Errors
    /// A texture beyond the device's limits.
    pub fn new(
        ctx: &GpuContext,
        pipelines: &Pipelines,
        cache: &SynthesisCache,
        heights: Option<&Array2<f64>>,
        tables: &MaterialTables,
    ) -> Result<Self> {
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
        // layer 0; the MRF pipelines skip missing layers).
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
        let extent = |layers: usize| wgpu::Extent3d {
            width: size as u32,
            height: size as u32,
            depth_or_array_layers: layers as u32,
        };
        let texture = |label, layers: usize, data: &[u8]| {
            device.create_texture_with_data(
                &ctx.queue,
                &wgpu::TextureDescriptor {
                    label: Some(label),
                    size: extent(layers),
                    mip_level_count: mip_levels(size),
                    sample_count: 1,
                    dimension: wgpu::TextureDimension::D2,
                    format: wgpu::TextureFormat::Rgba16Float,
                    usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
                    view_formats: &[],
                },
                wgpu::util::TextureDataOrder::LayerMajor,
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
        let storage = |label, bytes: &[u8]| {
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents: bytes,
                usage: wgpu::BufferUsages::STORAGE,
            })
        };
        let view_cells = storage("view cells", bytemuck::cast_slice(&tables.view_lut.cells));
        let light_cells = storage("light cells", bytemuck::cast_slice(&tables.light_lut.cells));
        let view_points = storage("view points", bytemuck::cast_slice(&tables.view_lut.points));
        let light_points = storage(
            "light points",
            bytemuck::cast_slice(&tables.light_lut.points),
        );
        let pair_layer = storage("pair layers", bytemuck::cast_slice(&tables.pair_layer));
        let ones = vec![1.0f32; super::lut::SHADING_GRID * super::lut::SHADING_GRID];
        let shading = tables.mean_shading.as_ref().map_or(&ones, |m| &m.values);
        let mean_shade = storage("mean shading", bytemuck::cast_slice(shading));
        let uniforms = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("globals"),
            size: std::mem::size_of::<Globals>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
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
        let buffers = [
            &view_cells,
            &light_cells,
            &view_points,
            &light_points,
            &pair_layer,
            &mean_shade,
        ];
        let mut entries = vec![
            wgpu::BindGroupEntry {
                binding: 0,
                resource: uniforms.as_entire_binding(),
            },
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
        ];
        for (i, b) in buffers.iter().enumerate() {
            entries.push(wgpu::BindGroupEntry {
                binding: 4 + i as u32,
                resource: b.as_entire_binding(),
            });
        }
        let bind_group = ctx.checked("material bind group", || {
            device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("material"),
                layout: &pipelines.layout,
                entries: &entries,
            })
        })?;
        Ok(Self {
            uniforms,
            bind_group,
            size,
            tile,
            counts: tables.counts,
            has_relief,
        })
    }

    /// Writes the uniforms of one frame.
    pub fn set_frame(&self, ctx: &GpuContext, scene: &Scene, mesh: &GpuMesh, plain_layer: u32) {
        let light = scene.light.to_vec4();
        let globals = Globals {
            view_proj: scene.camera.view_proj(scene.aspect()),
            camera: scene.camera.to_vec4(),
            light,
            params: [
                scene.light.distance.map_or(1.0, |d| d * d),
                if self.has_relief { 1.0 } else { 0.0 },
                mesh.world_per_uv / self.tile as f32,
                plain_layer as f32,
            ],
            counts: [self.counts.0 as u32, self.counts.1 as u32, 0, 0],
        };
        ctx.queue
            .write_buffer(&self.uniforms, 0, bytemuck::bytes_of(&globals));
    }
}

/// The render pipelines of every [`Mapping`] for one colour format.
#[derive(Debug)]
pub struct Pipelines {
    layout: wgpu::BindGroupLayout,
    pub(crate) lpca_layout: wgpu::BindGroupLayout,
    pipelines: HashMap<Mapping, wgpu::RenderPipeline>,
}

impl Pipelines {
    /// Compiles every pipeline for colour targets of `format`.
    ///
    /// # Errors
    /// A shader or pipeline the device rejects.
    pub fn new(ctx: &GpuContext, format: wgpu::TextureFormat) -> Result<Self> {
        let device = &ctx.device;
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
        let mut entries = vec![
            wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: vf,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Uniform,
                    has_dynamic_offset: false,
                    min_binding_size: None,
                },
                count: None,
            },
            texture(1, wgpu::TextureViewDimension::D2Array),
            texture(2, wgpu::TextureViewDimension::D2),
            wgpu::BindGroupLayoutEntry {
                binding: 3,
                visibility: vf,
                ty: wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering),
                count: None,
            },
        ];
        for binding in 4..10 {
            entries.push(wgpu::BindGroupLayoutEntry {
                binding,
                visibility: wgpu::ShaderStages::FRAGMENT,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Storage { read_only: true },
                    has_dynamic_offset: false,
                    min_binding_size: None,
                },
                count: None,
            });
        }
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("material"),
            entries: &entries,
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("mrf"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        // The LPCA pipeline: the uniforms and direction tables of common.wgsl (bindings 0,
        // 4..7) and its own model buffers (10..13, see shaders/lpca.wgsl).
        let storage = |binding| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::FRAGMENT,
            ty: wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Storage { read_only: true },
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        };
        let uniform = |binding| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: vf,
            ty: wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Uniform,
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        };
        let lpca_entries: Vec<_> = [uniform(0), uniform(10)]
            .into_iter()
            .chain([4, 5, 6, 7, 11, 12, 13].map(storage))
            .collect();
        let lpca_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("lpca model"),
            entries: &lpca_entries,
        });
        let lpca_pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("lpca"),
            bind_group_layouts: &[Some(&lpca_layout)],
            immediate_size: 0,
        });
        let mut pipelines = HashMap::new();
        for mapping in Mapping::ALL {
            let pipeline_layout = match mapping {
                Mapping::Lpca => &lpca_pipeline_layout,
                _ => &pipeline_layout,
            };
            let pipeline = ctx.checked(mapping.name(), || {
                let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
                    label: Some(mapping.name()),
                    source: wgpu::ShaderSource::Wgsl(shader_source(mapping).into()),
                });
                device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                    label: Some(mapping.name()),
                    layout: Some(pipeline_layout),
                    vertex: wgpu::VertexState {
                        module: &module,
                        entry_point: Some("vs_main"),
                        compilation_options: Default::default(),
                        buffers: &[Some(Vertex::layout())],
                    },
                    primitive: wgpu::PrimitiveState {
                        topology: wgpu::PrimitiveTopology::TriangleList,
                        front_face: wgpu::FrontFace::Ccw,
                        cull_mode: None,
                        ..Default::default()
                    },
                    depth_stencil: Some(wgpu::DepthStencilState {
                        format: DEPTH_FORMAT,
                        depth_write_enabled: Some(true),
                        depth_compare: Some(wgpu::CompareFunction::Less),
                        stencil: Default::default(),
                        bias: Default::default(),
                    }),
                    multisample: Default::default(),
                    fragment: Some(wgpu::FragmentState {
                        module: &module,
                        entry_point: Some("fs_main"),
                        compilation_options: Default::default(),
                        targets: &[Some(wgpu::ColorTargetState {
                            format,
                            blend: None,
                            write_mask: wgpu::ColorWrites::ALL,
                        })],
                    }),
                    multiview_mask: None,
                    cache: None,
                })
            })?;
            pipelines.insert(mapping, pipeline);
        }
        Ok(Self {
            layout,
            lpca_layout,
            pipelines,
        })
    }

    /// Records one draw of `mesh` with `material` into `pass` (an MRF mapping; the LPCA
    /// pipeline draws with [`Pipelines::draw_lpca`], and is ignored here).
    pub fn draw(
        &self,
        pass: &mut wgpu::RenderPass<'_>,
        mapping: Mapping,
        material: &GpuMaterial,
        mesh: &GpuMesh,
    ) {
        if mapping == Mapping::Lpca {
            return;
        }
        self.draw_with(pass, mapping, &material.bind_group, mesh);
    }

    /// Records one draw of `mesh` with an LPCA model into `pass`.
    pub fn draw_lpca(
        &self,
        pass: &mut wgpu::RenderPass<'_>,
        model: &super::lpca::GpuLpca,
        mesh: &GpuMesh,
    ) {
        self.draw_with(pass, Mapping::Lpca, &model.bind_group, mesh);
    }

    fn draw_with(
        &self,
        pass: &mut wgpu::RenderPass<'_>,
        mapping: Mapping,
        bind_group: &wgpu::BindGroup,
        mesh: &GpuMesh,
    ) {
        pass.set_pipeline(&self.pipelines[&mapping]);
        pass.set_bind_group(0, bind_group, &[]);
        pass.set_vertex_buffer(0, mesh.vertices.slice(..));
        pass.set_index_buffer(mesh.indices.slice(..), wgpu::IndexFormat::Uint32);
        pass.draw_indexed(0..mesh.count, 0, 0..1);
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
