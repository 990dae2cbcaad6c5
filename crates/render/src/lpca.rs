//! An LPCA model on the GPU: the decoding layout of Müller, Meseth and Klein (2003), with
//! buffers instead of textures (exact f32 copies of the model's half-float numbers).
//!
//! Per texel its cluster and `C` weights; per (cluster, measured view x light pair) the
//! cluster mean and `C` eigen-ABRDF values, RGB. The fragment shader (`shaders/lpca.wgsl`)
//! picks the texel nearest to the fragment's texture coordinates (the measured tile repeats)
//! and rebuilds its 3 x 3 nearest measured pairs exactly like
//! [`LpcaModel::reconstruct`](btfmrf::lpca::LpcaModel::reconstruct), blending them with the
//! barycentric weights of the direction tables ([`super::lut`]) that the MRF pipelines use.
//!
//! PCA RF models (one factorization per view, one cluster each) fit the same layout with the
//! view in place of the cluster; PCA BTF models (eigen-textures) do not and are refused.

use wgpu::util::DeviceExt;

use super::lut::DirectionLut;
use super::pipeline::{Globals, GpuMesh, Pipelines};
use super::scene::Scene;
use super::{GpuContext, RenderError, Result};
use btfmrf::lpca::{LpcaModel, Method};

/// The CPU side of [`GpuLpca`]: what it uploads.
#[derive(Debug, Clone)]
pub struct LpcaTables {
    /// Texture width and height, texels.
    pub size: (usize, usize),
    /// Components per cluster.
    pub components: usize,
    /// True for PCA RF (one factorization per view).
    pub per_view: bool,
    /// The cluster of every texel (LPCA), row-major.
    pub texel_cluster: Vec<u32>,
    /// `C` weights per texel (LPCA) or per (view, texel) (PCA RF).
    pub texel_weights: Vec<f32>,
    /// Per (group, pair, 0..=C): mean then eigen-ABRDF values as RGBA (A = 0).
    pub eigen: Vec<[f32; 4]>,
    /// Measured views and lights.
    pub counts: (usize, usize),
}

impl LpcaTables {
    /// The buffers of `model`.
    ///
    /// # Errors
    /// [`RenderError::Unsupported`] for a PCA BTF model.
    pub fn new(model: &LpcaModel) -> Result<Self> {
        let (nv, nl) = (model.views().len(), model.lights().len());
        let c = model.components();
        let n = model.width() * model.height();
        let per_view = match model.method() {
            Method::Lpca => false,
            Method::PcaRf => true,
            Method::PcaBtf => {
                return Err(RenderError::Unsupported(
                    "a pca-btf model (eigen-textures) does not render per fragment; \
                     fit an lpca (or pca-rf) model to render it"
                        .into(),
                ));
            }
        };
        let pairs = if per_view { nl } else { nv * nl };
        let mut eigen = Vec::new();
        let mut texel_weights = Vec::new();
        for f in model.parts() {
            let d = f.dim();
            if d != pairs * 3 || f.components() != c || f.items() != n {
                return Err(RenderError::Unsupported(format!(
                    "inconsistent {} model: vectors of {d} values for {pairs} pairs",
                    model.method().name()
                )));
            }
            for k in 0..f.clusters() {
                for p in 0..pairs {
                    eigen.extend(f.rgb_terms(k, 3 * p).map(|[r, g, b]| [r, g, b, 0.0]));
                }
            }
            texel_weights.extend_from_slice(f.weights());
        }
        let texel_cluster = if per_view {
            vec![0; n]
        } else {
            model.parts()[0]
                .assignment()
                .iter()
                .map(|&k| u32::from(k))
                .collect()
        };
        if texel_weights.is_empty() {
            texel_weights.push(0.0); // bindings may not be empty (C = 0)
        }
        Ok(Self {
            size: (model.width(), model.height()),
            components: c,
            per_view,
            texel_cluster,
            texel_weights,
            eigen,
            counts: (nv, nl),
        })
    }
}

/// An LPCA (or PCA RF) model's buffers and uniforms on the GPU, one bind group.
#[derive(Debug)]
pub struct GpuLpca {
    uniforms: wgpu::Buffer,
    pub(crate) bind_group: wgpu::BindGroup,
    counts: (usize, usize),
    /// Texture width, texels (scales nothing; reported).
    pub width: usize,
}

impl GpuLpca {
    /// Uploads `model` with its direction tables `luts` (views, lights).
    ///
    /// # Errors
    /// A PCA BTF model, or a buffer beyond the device's limits.
    pub fn new(
        ctx: &GpuContext,
        pipelines: &Pipelines,
        model: &LpcaModel,
        luts: &(DirectionLut, DirectionLut),
    ) -> Result<Self> {
        let tables = LpcaTables::new(model)?;
        let device = &ctx.device;
        let limit = device.limits().max_storage_buffer_binding_size;
        let eigen_bytes: &[u8] = bytemuck::cast_slice(&tables.eigen);
        let weight_bytes: &[u8] = bytemuck::cast_slice(&tables.texel_weights);
        for (what, len) in [
            ("eigen-ABRDFs", eigen_bytes.len()),
            ("texel weights", weight_bytes.len()),
        ] {
            if len as u64 > limit {
                return Err(RenderError::Unsupported(format!(
                    "the model's {what} take {len} bytes, above the device's storage buffer \
                     limit of {limit} bytes; fit fewer clusters or components"
                )));
            }
        }
        let storage = |label, bytes: &[u8]| {
            ctx.checked(label, || {
                device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some(label),
                    contents: bytes,
                    usage: wgpu::BufferUsages::STORAGE,
                })
            })
        };
        let buffers = [
            storage("view cells", bytemuck::cast_slice(&luts.0.cells))?,
            storage("light cells", bytemuck::cast_slice(&luts.1.cells))?,
            storage("view points", bytemuck::cast_slice(&luts.0.points))?,
            storage("light points", bytemuck::cast_slice(&luts.1.points))?,
            storage(
                "texel clusters",
                bytemuck::cast_slice(&tables.texel_cluster),
            )?,
            storage("texel weights", weight_bytes)?,
            storage("eigen-ABRDFs", eigen_bytes)?,
        ];
        let uniforms = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("globals"),
            size: std::mem::size_of::<Globals>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let info: [u32; 4] = [
            tables.size.0 as u32,
            tables.size.1 as u32,
            tables.components as u32,
            u32::from(tables.per_view),
        ];
        let info = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("lpca info"),
            contents: bytemuck::bytes_of(&info),
            usage: wgpu::BufferUsages::UNIFORM,
        });
        let mut entries = vec![
            wgpu::BindGroupEntry {
                binding: 0,
                resource: uniforms.as_entire_binding(),
            },
            wgpu::BindGroupEntry {
                binding: 10,
                resource: info.as_entire_binding(),
            },
        ];
        for (b, binding) in buffers.iter().zip([4, 5, 6, 7, 11, 12, 13]) {
            entries.push(wgpu::BindGroupEntry {
                binding,
                resource: b.as_entire_binding(),
            });
        }
        let bind_group = ctx.checked("lpca bind group", || {
            device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("lpca model"),
                layout: &pipelines.lpca_layout,
                entries: &entries,
            })
        })?;
        Ok(Self {
            uniforms,
            bind_group,
            counts: tables.counts,
            width: tables.size.0,
        })
    }

    /// Writes the uniforms of one frame (the point-light falloff as in the MRF pipelines).
    pub fn set_frame(&self, ctx: &GpuContext, scene: &Scene, _mesh: &GpuMesh) {
        let globals = Globals {
            view_proj: scene.camera.view_proj(scene.aspect()),
            camera: scene.camera.to_vec4(),
            light: scene.light.to_vec4(),
            params: [scene.light.distance.map_or(1.0, |d| d * d), 0.0, 0.0, 0.0],
            counts: [self.counts.0 as u32, self.counts.1 as u32, 0, 0],
        };
        ctx.queue
            .write_buffer(&self.uniforms, 0, bytemuck::bytes_of(&globals));
    }
}
