//! The procedural materials: for each, a periodic height field (meso-geometry) and a spatially
//! varying BRDF (albedo, specular strength, Blinn-Phong exponent) on the unit tile.

use super::noise::{Fbm, ValueNoise, Worley, rng};

/// What a material looks like at one point of the tile.
#[derive(Debug, Clone, Copy)]
pub(crate) struct SurfacePoint {
    /// Relative height; normalised to [0, 1] over the tile afterwards.
    pub height: f32,
    /// Diffuse albedo, linear RGB.
    pub albedo: [f32; 3],
    /// Specular strength (fraction of white light in the lobe).
    pub specular: f32,
    /// Blinn-Phong exponent of the lobe.
    pub shininess: f32,
}

/// A material pattern on the unit tile.
pub(crate) trait Pattern: Sync {
    /// The surface at tile coordinates (u, v) in [0, 1).
    fn at(&self, u: f32, v: f32) -> SurfacePoint;
    /// Peak-to-peak height as a fraction of the tile width.
    fn relief(&self) -> f32;
}

fn smoothstep(a: f32, b: f32, x: f32) -> f32 {
    let t = ((x - a) / (b - a)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

fn mix3(a: [f32; 3], b: [f32; 3], t: f32) -> [f32; 3] {
    std::array::from_fn(|c| a[c] + (b[c] - a[c]) * t)
}

fn scale3(a: [f32; 3], s: f32) -> [f32; 3] {
    a.map(|x| x * s)
}

/// Irregular porous foam: large and small round pores punched into a soft yellow body.
pub(crate) struct Sponge {
    pores: Worley,
    fine: Worley,
    body: Fbm,
    tint: Fbm,
}

impl Sponge {
    pub(crate) fn new(seed: u64) -> Self {
        let mut r = rng(seed, 1);
        Self {
            pores: Worley::new(9, 1.0, &mut r),
            fine: Worley::new(21, 1.0, &mut r),
            body: Fbm::new(4, 4, 0.5, &mut r),
            tint: Fbm::new(3, 3, 0.5, &mut r),
        }
    }
}

impl Pattern for Sponge {
    fn at(&self, u: f32, v: f32) -> SurfacePoint {
        let big = smoothstep(0.12, 0.55, self.pores.sample(u, v).f1);
        let small = smoothstep(0.10, 0.45, self.fine.sample(u, v).f1);
        let body = self.body.sample(u, v);
        let height = 0.6 * big + 0.25 * big * small + 0.15 * body;
        let base = scale3([0.78, 0.62, 0.26], 0.75 + 0.4 * self.tint.sample(u, v));
        // Pore interiors are darker: the foam's own inter-reflections and dirt.
        let albedo = scale3(base, 0.5 + 0.5 * big * (0.6 + 0.4 * small));
        SurfacePoint {
            height,
            albedo,
            specular: 0.02,
            shininess: 6.0,
        }
    }

    fn relief(&self) -> f32 {
        0.07
    }
}

/// A plain weave: red warp threads along v over and under cream weft threads along u.
pub(crate) struct Knit {
    threads: f32,
    warp_fibres: ValueNoise,
    weft_fibres: ValueNoise,
}

impl Knit {
    pub(crate) fn new(seed: u64) -> Self {
        let mut r = rng(seed, 2);
        Self {
            threads: 8.0,
            warp_fibres: ValueNoise::anisotropic(96, 12, &mut r),
            weft_fibres: ValueNoise::anisotropic(12, 96, &mut r),
        }
    }
}

impl Pattern for Knit {
    fn at(&self, u: f32, v: f32) -> SurfacePoint {
        let (x, y) = (u * self.threads, v * self.threads);
        let (k, r) = (x.floor(), y.floor());
        let (dx, dy) = (x - k - 0.5, y - r - 0.5);
        let profile = |d: f32| (1.0 - (d / 0.44).powi(2)).max(0.0).sqrt();
        let pi = std::f32::consts::PI;
        // Warp k is on top at weft rows r with r - k even, the weft on the others.
        let warp_lift = 0.5 + 0.5 * (pi * (y - 0.5 - k)).cos();
        let weft_lift = 0.5 - 0.5 * (pi * (x - 0.5 - r)).cos();
        let fw = self.warp_fibres.sample(u, v);
        let ff = self.weft_fibres.sample(u, v);
        let warp = profile(dx) * (0.45 + 0.55 * warp_lift) * (0.9 + 0.1 * fw);
        let weft = profile(dy) * (0.45 + 0.55 * weft_lift) * (0.9 + 0.1 * ff);
        let (top, colour, fibre) = if warp >= weft {
            (warp, [0.62, 0.12, 0.14], fw)
        } else {
            (weft, [0.86, 0.80, 0.66], ff)
        };
        let thread = scale3(colour, 0.85 + 0.15 * fibre);
        let albedo = mix3([0.05, 0.04, 0.04], thread, smoothstep(0.0, 0.35, top));
        SurfacePoint {
            height: top,
            albedo,
            specular: 0.04,
            shininess: 12.0,
        }
    }

    fn relief(&self) -> f32 {
        0.045
    }
}

/// Rounded cobbles of several colours set in light sandy grout.
pub(crate) struct Stones {
    cells: Worley,
    rough: Fbm,
    tint: Fbm,
}

impl Stones {
    pub(crate) fn new(seed: u64) -> Self {
        let mut r = rng(seed, 3);
        Self {
            cells: Worley::new(5, 0.9, &mut r),
            rough: Fbm::new(8, 4, 0.5, &mut r),
            tint: Fbm::new(6, 3, 0.5, &mut r),
        }
    }
}

impl Pattern for Stones {
    fn at(&self, u: f32, v: f32) -> SurfacePoint {
        const PALETTE: [[f32; 3]; 4] = [
            [0.45, 0.44, 0.42],
            [0.50, 0.38, 0.28],
            [0.62, 0.52, 0.36],
            [0.28, 0.28, 0.30],
        ];
        let c = self.cells.sample(u, v);
        let edge = c.f2 - c.f1;
        let rough = self.rough.sample(u, v);
        let stature = 0.75 + 0.25 * self.cells.cell_value(c.id, 1);
        // A rounded shoulder near the grout and a gently domed top (not a ridge along the
        // cell's medial axis, which the raw edge distance would give).
        let t = smoothstep(0.03, 0.3, edge);
        let dome = (1.0 - (1.0 - t) * (1.0 - t)).sqrt() * (1.0 - 0.15 * c.f1 * c.f1);
        let height = dome * stature + 0.07 * rough;
        let pick = (self.cells.cell_value(c.id, 2) * PALETTE.len() as f32) as usize;
        let stone = scale3(
            PALETTE[pick.min(PALETTE.len() - 1)],
            0.8 + 0.4 * self.tint.sample(u, v),
        );
        let grout = scale3([0.68, 0.66, 0.60], 0.85 + 0.3 * rough);
        let t = smoothstep(0.03, 0.09, edge);
        SurfacePoint {
            height,
            albedo: mix3(grout, stone, t),
            specular: 0.01 + 0.05 * t,
            shininess: 25.0,
        }
    }

    fn relief(&self) -> f32 {
        0.09
    }
}

/// Fine, irregular grain: small glossy plateaus separated by a network of dark creases.
pub(crate) struct Leather {
    grain: Worley,
    fine: Fbm,
    blotch: Fbm,
}

impl Leather {
    pub(crate) fn new(seed: u64) -> Self {
        let mut r = rng(seed, 4);
        Self {
            grain: Worley::new(26, 1.0, &mut r),
            fine: Fbm::new(16, 3, 0.5, &mut r),
            blotch: Fbm::new(3, 3, 0.5, &mut r),
        }
    }
}

impl Pattern for Leather {
    fn at(&self, u: f32, v: f32) -> SurfacePoint {
        let c = self.grain.sample(u, v);
        let crease = 1.0 - smoothstep(0.0, 0.18, c.f2 - c.f1);
        let plateau = 1.0 - 0.25 * c.f1 * c.f1;
        let height = plateau * (1.0 - 0.7 * crease) + 0.15 * self.fine.sample(u, v);
        let base = scale3([0.30, 0.15, 0.07], 0.8 + 0.4 * self.blotch.sample(u, v));
        SurfacePoint {
            height,
            albedo: scale3(base, 1.0 - 0.35 * crease),
            specular: 0.12 * (1.0 - 0.5 * crease),
            shininess: 35.0,
        }
    }

    fn relief(&self) -> f32 {
        0.02
    }
}
