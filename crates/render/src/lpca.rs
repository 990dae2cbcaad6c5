//! The LPCA material on the GPU: the decoding layout of Müller, Meseth and Klein (2003), with
//! buffers instead of textures (exact f32 copies of the model's half-float numbers), and the
//! pass that draws it.
//!
//! Per texel its cluster and `C` weights; per (cluster, measured view x light pair) the
//! cluster mean and `C` eigen-ABRDF values, RGB. The fragment shader (`shaders/lpca.wgsl`)
//! picks the texel nearest to the fragment's texture coordinates (the measured tile repeats)
//! and rebuilds its 3 x 3 nearest measured pairs exactly like
//! [`LpcaModel::reconstruct`](btfmrf::lpca::LpcaModel::reconstruct), blending them with the
//! barycentric weights of the direction tables ([`super::lut`]) that the MRF pass uses. The
//! mesh is drawn as it is: an LPCA model has no range map to bump or displace it by.
//!
//! PCA RF models (one factorization per view, one cluster each) fit the same layout with the
//! view in place of the cluster; PCA BTF models (eigen-textures) do not and are refused.

use wgpu::util::DeviceExt;

use super::lut::DirectionLut;
use super::pipeline::{
    COMMON_WGSL, CommonBuffers, GpuMesh, bind_group_layout, common_layout_entries, render_pipeline,
    storage_buffer, storage_entry, uniform_entry,
};
use super::scene::Scene;
use super::{GpuContext, RenderError, Result};
use btfmrf::lpca::{LpcaModel, Method};

const LPCA_WGSL: &str = include_str!("../../../shaders/lpca.wgsl");

/// The WGSL source of the LPCA pipeline: `common.wgsl`, then `lpca.wgsl`.
pub fn shader_source() -> String {
    format!("{COMMON_WGSL}\n{LPCA_WGSL}")
}

/// Where row `row` (0: the mean, `1..=components`: the eigen-ABRDFs) of measured pair `pair`
/// of `group` (cluster, or view for PCA RF) sits in [`LpcaTables::eigen`], for `pairs` pairs
/// per group: `(group * pairs + pair) * (components + 1) + row`. The shader's `eigen_slot` in
/// `lpca.wgsl` is the same formula.
pub fn eigen_slot(group: usize, pair: usize, row: usize, pairs: usize, components: usize) -> usize {
    (group * pairs + pair) * (components + 1) + row
}

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
    /// Means and eigen-ABRDF values as RGBA (A = 0), at [`eigen_slot`].
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
        let mut group0 = 0;
        for f in model.parts() {
            let d = f.dim();
            if d != pairs * 3 || f.components() != c || f.items() != n {
                return Err(RenderError::Unsupported(format!(
                    "inconsistent {} model: vectors of {d} values for {pairs} pairs",
                    model.method().name()
                )));
            }
            let groups = f.clusters();
            eigen.resize((group0 + groups) * pairs * (c + 1), [0.0; 4]);
            for k in 0..groups {
                for p in 0..pairs {
                    for (r, [x, y, z]) in f.rgb_terms(k, 3 * p).enumerate() {
                        eigen[eigen_slot(group0 + k, p, r, pairs, c)] = [x, y, z, 0.0];
                    }
                }
            }
            group0 += groups;
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

/// An LPCA (or PCA RF) model's buffers and uniforms on the GPU, bound as group 0 of
/// [`LpcaPass`].
#[derive(Debug)]
pub struct GpuLpca {
    common: CommonBuffers,
    bind_group: wgpu::BindGroup,
}

impl GpuLpca {
    /// Uploads `model` with its direction tables `luts` (views, lights), for `pass`.
    ///
    /// # Errors
    /// A PCA BTF model, or a buffer beyond the device's limits.
    pub fn new(
        ctx: &GpuContext,
        pass: &LpcaPass,
        model: &LpcaModel,
        luts: (&DirectionLut, &DirectionLut),
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
        let common = CommonBuffers::new(ctx, luts)?;
        let buffers = [
            storage_buffer(
                ctx,
                "texel clusters",
                bytemuck::cast_slice(&tables.texel_cluster),
            )?,
            storage_buffer(ctx, "texel weights", weight_bytes)?,
            storage_buffer(ctx, "eigen-ABRDFs", eigen_bytes)?,
        ];
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
        let mut entries = common.entries();
        entries.push(wgpu::BindGroupEntry {
            binding: 10,
            resource: info.as_entire_binding(),
        });
        for (b, binding) in buffers.iter().zip(11..) {
            entries.push(wgpu::BindGroupEntry {
                binding,
                resource: b.as_entire_binding(),
            });
        }
        let bind_group = ctx.checked("lpca bind group", || {
            device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("lpca model"),
                layout: &pass.layout,
                entries: &entries,
            })
        })?;
        Ok(Self { common, bind_group })
    }

    /// Writes the uniforms of one frame (the point-light falloff as in the MRF pass).
    pub fn set_frame(&self, ctx: &GpuContext, scene: &Scene) {
        self.common.write(ctx, scene, ([0.0; 3], [0.0; 4]));
    }
}

/// The LPCA material's bind group layout and pipeline, for one colour format.
#[derive(Debug)]
pub struct LpcaPass {
    layout: wgpu::BindGroupLayout,
    pipeline: wgpu::RenderPipeline,
}

impl LpcaPass {
    /// Compiles the pipeline for colour targets of `format`.
    ///
    /// # Errors
    /// A shader or pipeline the device rejects.
    pub fn new(ctx: &GpuContext, format: wgpu::TextureFormat) -> Result<Self> {
        let mut entries = common_layout_entries().to_vec();
        entries.extend([
            uniform_entry(10, wgpu::ShaderStages::VERTEX_FRAGMENT),
            storage_entry(11),
            storage_entry(12),
            storage_entry(13),
        ]);
        let layout = bind_group_layout(ctx, "lpca model", &entries);
        let pipeline = render_pipeline(ctx, "lpca", &layout, shader_source(), format)?;
        Ok(Self { layout, pipeline })
    }

    /// Records one draw of `mesh` with `model` into `pass`.
    pub fn draw(&self, pass: &mut wgpu::RenderPass<'_>, model: &GpuLpca, mesh: &GpuMesh) {
        mesh.draw(pass, &self.pipeline, &model.bind_group);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn eigen_slots_are_dense_and_in_group_pair_row_order() {
        let (groups, pairs, c) = (3, 5, 2);
        let mut next = 0;
        for g in 0..groups {
            for p in 0..pairs {
                for r in 0..=c {
                    assert_eq!(eigen_slot(g, p, r, pairs, c), next);
                    next += 1;
                }
            }
        }
        assert_eq!(next, groups * pairs * (c + 1));
    }
}
