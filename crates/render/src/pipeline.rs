//! What every material's pass shares: the `Globals` uniforms, the direction-table buffers, the
//! mesh on the GPU, and the construction of a render pipeline from WGSL.
//!
//! `shaders/common.wgsl` declares what this module binds (group 0: the uniforms at binding 0,
//! the direction tables at 4..7) and the helpers every material's shader uses; each material
//! adds its own bindings in its own file ([`super::mrf`]: `mrf.wgsl`, [`super::lpca`]:
//! `lpca.wgsl`). A material is a pass type owning its bind group layout and pipelines.

use wgpu::util::DeviceExt;

use super::frame::DEPTH_FORMAT;
use super::lut::DirectionLut;
use super::mesh::{Mesh, Vertex};
use super::scene::Scene;
use super::{GpuContext, Result};

/// The helpers and shared bindings, prepended to every pipeline's WGSL.
pub const COMMON_WGSL: &str = include_str!("../../../shaders/common.wgsl");

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
    /// Squared light distance, then three values of the material's own (see its shader).
    pub params: [f32; 4],
    /// Measured views, measured lights.
    pub counts: [u32; 4],
    /// Where view and light directions are clamped ([`DirectionLut::max_theta`], radians),
    /// then the light's [`DirectionLut::horizon_z`].
    pub limits: [f32; 4],
    /// The material's relief heights (see its shader).
    pub relief: [f32; 4],
}

impl Globals {
    /// The uniforms of one frame of `scene`: `template` holds `counts` and `limits`, `own`
    /// the material's `params.yzw` and `relief`.
    fn new(scene: &Scene, template: &Globals, (own, relief): ([f32; 3], [f32; 4])) -> Self {
        Self {
            view_proj: scene.camera.view_proj(scene.aspect()),
            camera: scene.camera.to_vec4(),
            light: scene.light.to_vec4(),
            params: [
                scene.light.distance.map_or(1.0, |d| d * d),
                own[0],
                own[1],
                own[2],
            ],
            counts: template.counts,
            limits: template.limits,
            relief,
        }
    }
}

/// The uniform buffer of [`Globals`], written once per frame.
pub(crate) fn globals_buffer(ctx: &GpuContext) -> wgpu::Buffer {
    ctx.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("globals"),
        size: std::mem::size_of::<Globals>() as u64,
        usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    })
}

/// A read-only storage buffer holding `bytes`.
///
/// # Errors
/// A buffer the device refuses.
pub(crate) fn storage_buffer(ctx: &GpuContext, label: &str, bytes: &[u8]) -> Result<wgpu::Buffer> {
    ctx.checked(label, || {
        ctx.device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents: bytes,
                usage: wgpu::BufferUsages::STORAGE,
            })
    })
}

/// Layout entry of a uniform buffer at `binding`.
pub(crate) fn uniform_entry(
    binding: u32,
    visibility: wgpu::ShaderStages,
) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Uniform,
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}

/// Layout entry of a read-only storage buffer at `binding`, for the fragment stage.
pub(crate) fn storage_entry(binding: u32) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::FRAGMENT,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Storage { read_only: true },
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}

/// The bindings `common.wgsl` declares: the uniforms (0) and the direction tables (4..7).
pub(crate) fn common_layout_entries() -> [wgpu::BindGroupLayoutEntry; 5] {
    [
        uniform_entry(0, wgpu::ShaderStages::VERTEX_FRAGMENT),
        storage_entry(4),
        storage_entry(5),
        storage_entry(6),
        storage_entry(7),
    ]
}

/// The uniforms and direction tables of one material on the GPU: what `common.wgsl` binds.
#[derive(Debug)]
pub(crate) struct CommonBuffers {
    /// The uniforms that come from the tables (`counts`, `limits`; the rest zero).
    template: Globals,
    globals: wgpu::Buffer,
    /// View cells, light cells, view points, light points (bindings 4..7).
    tables: [wgpu::Buffer; 4],
}

impl CommonBuffers {
    /// Uploads the direction tables `luts` (views, lights).
    ///
    /// # Errors
    /// A buffer the device refuses.
    pub(crate) fn new(ctx: &GpuContext, luts: (&DirectionLut, &DirectionLut)) -> Result<Self> {
        let template = Globals {
            counts: [luts.0.points.len() as u32, luts.1.points.len() as u32, 0, 0],
            limits: [
                luts.0.max_theta as f32,
                luts.1.max_theta as f32,
                luts.1.horizon_z() as f32,
                luts.1.fade_z() as f32,
            ],
            ..bytemuck::Zeroable::zeroed()
        };
        Ok(Self {
            template,
            globals: globals_buffer(ctx),
            tables: [
                storage_buffer(ctx, "view cells", bytemuck::cast_slice(&luts.0.cells))?,
                storage_buffer(ctx, "light cells", bytemuck::cast_slice(&luts.1.cells))?,
                storage_buffer(ctx, "view points", bytemuck::cast_slice(&luts.0.points))?,
                storage_buffer(ctx, "light points", bytemuck::cast_slice(&luts.1.points))?,
            ],
        })
    }

    /// The bind group entries of [`common_layout_entries`].
    pub(crate) fn entries(&self) -> Vec<wgpu::BindGroupEntry<'_>> {
        let mut entries = vec![wgpu::BindGroupEntry {
            binding: 0,
            resource: self.globals.as_entire_binding(),
        }];
        for (b, binding) in self.tables.iter().zip(4..) {
            entries.push(wgpu::BindGroupEntry {
                binding,
                resource: b.as_entire_binding(),
            });
        }
        entries
    }

    /// Writes the uniforms of one frame of `scene`; `own` are the material's `params.yzw` and
    /// `relief`.
    pub(crate) fn write(&self, ctx: &GpuContext, scene: &Scene, own: ([f32; 3], [f32; 4])) {
        let globals = Globals::new(scene, &self.template, own);
        ctx.queue
            .write_buffer(&self.globals, 0, bytemuck::bytes_of(&globals));
    }
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

    /// Records one draw of this mesh with `pipeline` and its `bind_group` (group 0).
    pub(crate) fn draw(
        &self,
        pass: &mut wgpu::RenderPass<'_>,
        pipeline: &wgpu::RenderPipeline,
        bind_group: &wgpu::BindGroup,
    ) {
        pass.set_pipeline(pipeline);
        pass.set_bind_group(0, bind_group, &[]);
        pass.set_vertex_buffer(0, self.vertices.slice(..));
        pass.set_index_buffer(self.indices.slice(..), wgpu::IndexFormat::Uint32);
        pass.draw_indexed(0..self.count, 0, 0..1);
    }
}

/// A render pipeline layout of one bind group (group 0) with `entries`.
pub(crate) fn bind_group_layout(
    ctx: &GpuContext,
    label: &str,
    entries: &[wgpu::BindGroupLayoutEntry],
) -> wgpu::BindGroupLayout {
    ctx.device
        .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some(label),
            entries,
        })
}

/// Whether a colour target of `format` clips to [0, 1] (all but the float formats): its
/// fragments are fitted to the gamut first (`displayed` in common.wgsl).
fn clips(format: wgpu::TextureFormat) -> bool {
    !matches!(
        format,
        wgpu::TextureFormat::Rgba16Float
            | wgpu::TextureFormat::Rgba32Float
            | wgpu::TextureFormat::Rg11b10Ufloat
    )
}

/// Compiles `source` (entry points `vs_main`, `fs_main`; vertices as [`Vertex`]) into a
/// triangle pipeline with depth test for colour targets of `format`, bound by `layout`;
/// targets that clip get their colour fitted to the gamut ([`clips`]).
///
/// # Errors
/// A shader or pipeline the device rejects.
pub(crate) fn render_pipeline(
    ctx: &GpuContext,
    label: &str,
    layout: &wgpu::BindGroupLayout,
    source: String,
    format: wgpu::TextureFormat,
) -> Result<wgpu::RenderPipeline> {
    let device = &ctx.device;
    ctx.checked(label, || {
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some(label),
            bind_group_layouts: &[Some(layout)],
            immediate_size: 0,
        });
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some(label),
            source: wgpu::ShaderSource::Wgsl(source.into()),
        });
        device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some(label),
            layout: Some(&pipeline_layout),
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
                compilation_options: wgpu::PipelineCompilationOptions {
                    constants: &[("FIT_TO_DISPLAY", f64::from(u8::from(clips(format))))],
                    ..Default::default()
                },
                targets: &[Some(wgpu::ColorTargetState {
                    format,
                    blend: None,
                    write_mask: wgpu::ColorWrites::ALL,
                })],
            }),
            multiview_mask: None,
            cache: None,
        })
    })
}
