//! Model only what a scene needs: which clusters the visible surface touches, and the texture
//! resolution its screen footprint asks for.
//!
//! The plan samples the mesh on the CPU at every front-facing vertex and triangle centre in
//! the view frustum, takes view and light into the tangent frame there, and interpolates them
//! with the same tables as the shader ([`DirectionLut::lookup`]); every cluster of a pair with
//! a non-zero weight is needed. Fragments between samples can, rarely, reach a cluster no
//! sample did; the shader then skips it and renormalises the remaining weights.

use std::collections::BTreeSet;

use super::lut::DirectionLut;
use super::mesh::Mesh;
use super::scene::Scene;
use btfmrf::model::MaterialModel;

/// What to synthesize for one scene.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ScenePlan {
    /// The clusters (subspace images) the visible surface draws on, ascending.
    pub clusters: Vec<usize>,
    /// The measured (view, light) pairs the visible surface draws on that have parts of
    /// their own ([`MaterialModel::has_own_parts`]), ascending: their finishes
    /// ([`MaterialModel::pair_finish`]) are made and uploaded.
    pub finishes: Vec<(usize, usize)>,
    /// Texture side on the GPU, texels (how finely one repetition is sampled, not what it
    /// holds): the power of two nearest (on a log scale) to the largest screen
    /// footprint of one texture repetition, in pixels, within `[min, max]` of [`plan_scene`].
    pub texture_size: usize,
}

fn sub(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn to_frame(v: [f32; 3], t: [f32; 3], b: [f32; 3], n: [f32; 3]) -> [f64; 3] {
    let len = dot(v, v).sqrt().max(1e-12);
    [dot(v, t), dot(v, b), dot(v, n)].map(|x| f64::from(x / len))
}

/// Plans `scene` for `mesh`: the clusters needed and a texture side between `min_size` and
/// `max_size` (powers of two).
pub fn plan_scene(
    model: &MaterialModel,
    mesh: &Mesh,
    scene: &Scene,
    luts: (&DirectionLut, &DirectionLut),
    (min_size, max_size): (usize, usize),
) -> ScenePlan {
    let m = scene.camera.view_proj(scene.aspect());
    let clip = |p: [f32; 3]| -> [f32; 4] {
        std::array::from_fn(|r| m[0][r] * p[0] + m[1][r] * p[1] + m[2][r] * p[2] + m[3][r])
    };
    let camera = scene.camera.to_vec4();
    let light = scene.light.to_vec4();
    let inside = |c: [f32; 4]| {
        c[3] > 0.0 && c[0].abs() <= 1.05 * c[3] && c[1].abs() <= 1.05 * c[3] && c[2] >= 0.0
    };
    let mut clusters = BTreeSet::new();
    let mut finishes = BTreeSet::new();
    let mut sample = |p: [f32; 3], n: [f32; 3], tangent: [f32; 4]| {
        let t = [tangent[0], tangent[1], tangent[2]];
        let b = {
            let c = [
                n[1] * t[2] - n[2] * t[1],
                n[2] * t[0] - n[0] * t[2],
                n[0] * t[1] - n[1] * t[0],
            ];
            c.map(|x| x * tangent[3])
        };
        let v_world = if camera[3] > 0.5 {
            sub([camera[0], camera[1], camera[2]], p)
        } else {
            [camera[0], camera[1], camera[2]]
        };
        let v = to_frame(v_world, t, b, n);
        let l_world = if light[3] > 0.5 {
            sub([light[0], light[1], light[2]], p)
        } else {
            [light[0], light[1], light[2]]
        };
        let l = to_frame(l_world, t, b, n);
        if v[2] <= 0.0 || l[2] <= luts.1.horizon_z() {
            return;
        }
        let (vi, vw) = luts.0.lookup(v);
        let (li, lw) = luts.1.lookup(l);
        for a in 0..3 {
            for c in 0..3 {
                if vw[a] * lw[c] > 0.0 {
                    let k = model.cluster_of(vi[a], li[c]);
                    clusters.insert(k.expect("the lookup tables index the model's directions"));
                    if model.has_own_parts(vi[a], li[c]) {
                        finishes.insert((vi[a], li[c]));
                    }
                }
            }
        }
    };
    let mut texels_per_uv = 0.0f64;
    let (w, h) = (f64::from(scene.width), f64::from(scene.height));
    for tri in mesh.indices.chunks_exact(3) {
        let vs = [tri[0], tri[1], tri[2]].map(|i| mesh.vertices[i as usize]);
        let cs = vs.map(|v| clip(v.position));
        if !cs.iter().any(|&c| inside(c)) {
            continue;
        }
        // Every frame a fragment may blend (its own and those beyond a nearby edge).
        for v in &vs {
            if inside(clip(v.position)) {
                for tangent in v.frames() {
                    sample(v.position, v.normal, tangent);
                }
            }
        }
        let centre: [f32; 3] = std::array::from_fn(|k| {
            (vs[0].position[k] + vs[1].position[k] + vs[2].position[k]) / 3.0
        });
        let normal: [f32; 3] =
            std::array::from_fn(|k| vs[0].normal[k] + vs[1].normal[k] + vs[2].normal[k]);
        let nlen = dot(normal, normal).sqrt().max(1e-12);
        let normal = normal.map(|x| x / nlen);
        for tangent in vs[0].frames() {
            let t = [tangent[0], tangent[1], tangent[2]];
            let t = sub(t, normal.map(|x| x * dot(normal, t)));
            let tlen = dot(t, t).sqrt();
            if tlen > 1e-6 {
                sample(
                    centre,
                    normal,
                    [t[0] / tlen, t[1] / tlen, t[2] / tlen, tangent[3]],
                );
            }
        }
        // Screen footprint: pixels per texture repetition (all vertices in front).
        if cs.iter().all(|c| c[3] > 1e-6) {
            let s = cs.map(|c| {
                [
                    f64::from(c[0] / c[3]) * w / 2.0,
                    f64::from(c[1] / c[3]) * h / 2.0,
                ]
            });
            let screen = ((s[1][0] - s[0][0]) * (s[2][1] - s[0][1])
                - (s[2][0] - s[0][0]) * (s[1][1] - s[0][1]))
                .abs();
            let uv = f64::from(
                ((vs[1].uv[0] - vs[0].uv[0]) * (vs[2].uv[1] - vs[0].uv[1])
                    - (vs[2].uv[0] - vs[0].uv[0]) * (vs[1].uv[1] - vs[0].uv[1]))
                    .abs(),
            );
            if uv > 1e-12 {
                texels_per_uv = texels_per_uv.max((screen / uv).sqrt());
            }
        }
    }
    // The nearest power of two on a log scale: texels at most sqrt(2) larger or smaller than
    // pixels (trilinear filtering covers that).
    let wanted = 1usize << (texels_per_uv.max(1.0).log2().round() as u32).min(30);
    ScenePlan {
        clusters: clusters.into_iter().collect(),
        finishes: finishes.into_iter().collect(),
        texture_size: wanted.clamp(min_size, max_size.max(min_size)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{Camera, Light, Projection};
    use btfmrf::btf::{Direction, DirectionSet};
    use btfmrf::decompose::marginals::{QUANTILES, QuantileGrid};
    use btfmrf::decompose::{ColourSpace, KlBasis};
    use btfmrf::model::{MaterialParts, SubspaceModel};
    use btfmrf::mrf::{Car2dModel, Levels};

    /// A model skeleton whose cluster of a pair is `light index % 4` (constant band models:
    /// the plan reads only the directions and the cluster table).
    fn skeleton() -> MaterialModel {
        let (views, lights) = (DirectionSet::bonn(), DirectionSet::bonn());
        let cluster_table = (0..81 * 81).map(|i| (i % 81 % 4) as u16).collect();
        let flat = SubspaceModel {
            representative: (0, 0),
            kl: KlBasis::identity(ColourSpace::LinearRgb),
            marginals: [[0.0; QUANTILES]; 3],
            marginal_grid: QuantileGrid::Uniform,
            levels: Levels::new(vec![vec![Car2dModel::constant(0.0); 3]])
                .unwrap()
                .into(),
            band_marginals: None,
            colour_marginals: None,
            lit_marginals: None,
        };
        MaterialModel::new(MaterialParts {
            views,
            lights,
            width: 64,
            height: 64,
            cluster_table,
            subspaces: vec![flat; 4],
            range_map: None,
            exemplar: None,
            periodic: None,
            pair_gains: Vec::new(),
            light_lightness: None,
        })
        .unwrap()
    }

    #[test]
    fn a_flat_plane_under_one_view_and_light_needs_the_cpu_clusters_only() {
        let model = skeleton();
        let luts = (
            DirectionLut::new(model.views()).unwrap(),
            DirectionLut::new(model.lights()).unwrap(),
        );
        let light = Direction::new(45.0, 30.0);
        let scene = Scene {
            camera: Camera {
                direction: Direction::new(0.0, 0.0),
                distance: 3.0,
                projection: Projection::Orthographic { half_height: 1.0 },
            },
            light: Light {
                direction: light,
                distance: None,
            },
            width: 256,
            height: 256,
        };
        let mesh = Mesh::plane(8, 1.0);
        let plan = plan_scene(&model, &mesh, &scene, (&luts.0, &luts.1), (32, 4096));
        let cpu: Vec<usize> = model
            .subspace_weights(&Direction::new(0.0, 0.0), &light)
            .unwrap()
            .into_keys()
            .collect();
        assert_eq!(plan.clusters, cpu);
        // The skeleton has no parts of any light's own.
        assert!(plan.finishes.is_empty());
        // One repetition covers 256 pixels.
        assert_eq!(plan.texture_size, 256);
        // A sphere seen from an angle touches more light directions than a plane.
        let sphere = Mesh::sphere(8, 1.0);
        let wide = plan_scene(&model, &sphere, &scene, (&luts.0, &luts.1), (32, 4096));
        assert!(plan.clusters.len() < 4);
        assert_eq!(wide.clusters, vec![0, 1, 2, 3]);
    }
}
