//! Vegetation for the synthetic scenes (`talus synth vegetation`): shrubs, grass tufts and trees
//! as a scanner samples them — leaves scattered through a crown, mostly its outer part, stems
//! and blades as lines, a trunk as a thin cylinder — and the ground behind them partly hidden.
//! They change between surveys without any material moving: grown, resampled, or cut.
//!
//! A plant is not a surface, so it has no patch: its points are drawn here, after the surfaces',
//! with their own random stream per plant and epoch, and the surface points behind a crown are
//! thinned by a hash of their coordinates (so which ones are hidden does not depend on how the
//! surfaces were chunked).

use super::surface::V3;
use talus_base::rng::Rng;

/// What a plant is, for its shape and its LAS class when the delivery is classified (LAS 1.4
/// R15 Table 17: 3 low, 4 medium, 5 high vegetation).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum PlantKind {
    /// A crown of leaves (an ellipsoid).
    Shrub,
    /// Grass blades from one root: lines a few decimetres long.
    Tuft,
    /// A trunk (cylinder) under a crown.
    Tree,
}

/// Where a plant stands: on the ground (its crown over its footprint) or on a vertical face in
/// the plane y = 0 (its crown in front of it, toward −y).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Standing {
    Ground,
    Face,
}

/// One plant in one epoch (local coordinates).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Plant {
    pub kind: PlantKind,
    pub standing: Standing,
    /// Its root: on the ground (x, y, ground height), or on the face (x, 0, z).
    pub root: V3,
    /// The crown's semi-axes (x, y, z); a tuft's: its spread and blade height.
    pub size: V3,
    /// A stream number of its own (its points do not depend on the other plants').
    pub stream: u64,
}

/// Share of the surface points behind a crown that the crown hides from the scanner.
pub(crate) const HIDDEN: f64 = 0.6;

impl Plant {
    /// The LAS class of its points in a classified delivery.
    pub(crate) fn class(&self) -> u8 {
        match self.kind {
            PlantKind::Tuft => 3,
            PlantKind::Shrub => 4,
            PlantKind::Tree => 5,
        }
    }

    /// The plant grown by `factor` (every dimension).
    pub(crate) fn grown(mut self, factor: f64, stream: u64) -> Plant {
        self.size = self.size.map(|s| s * factor);
        self.stream = stream;
        self
    }

    /// The crown's centre.
    fn crown(&self) -> V3 {
        let [x, y, z] = self.root;
        match (self.kind, self.standing) {
            (PlantKind::Tree, _) => [x, y, z + 2.5 * self.size[2]],
            (_, Standing::Ground) => [x, y, z + self.size[2] + 0.05],
            (_, Standing::Face) => [x, y - self.size[1], z],
        }
    }

    /// Whether the crown hides surface point `p` from a scanner looking at the surface (from
    /// above on the ground, from −y on the face): `p` lies in the crown's shadow.
    fn shadows(&self, p: &V3) -> bool {
        if self.kind == PlantKind::Tuft {
            return false;
        }
        let c = self.crown();
        let s = self.size;
        match self.standing {
            Standing::Ground => {
                p[2] < c[2] && ((p[0] - c[0]) / s[0]).powi(2) + ((p[1] - c[1]) / s[1]).powi(2) < 1.0
            }
            Standing::Face => {
                p[1] > c[1] && ((p[0] - c[0]) / s[0]).powi(2) + ((p[2] - c[2]) / s[2]).powi(2) < 1.0
            }
        }
    }

    /// The plant's points at `density` points per m² of the scene's surfaces, from epoch
    /// `epoch`'s stream under `seed`.
    pub(crate) fn points(&self, density: f64, seed: u64, epoch: u64) -> Vec<V3> {
        let mut rng = Rng::new(
            seed ^ 0x005e_ed0f_1eaf,
            (epoch << 40) | (1 << 39) | self.stream,
        );
        let mut out = Vec::new();
        match self.kind {
            PlantKind::Shrub | PlantKind::Tree => {
                let c = self.crown();
                let s = self.size;
                // A scanner sees about the crown's outer surface's worth of points (Knud Thomsen's
                // approximation of an ellipsoid's area), scattered below it.
                let p = 1.6075;
                let area = 4.0
                    * std::f64::consts::PI
                    * (((s[0] * s[1]).powf(p) + (s[0] * s[2]).powf(p) + (s[1] * s[2]).powf(p))
                        / 3.0)
                        .powf(1.0 / p);
                let n = (area * density) as usize;
                let depth = 0.3 * s.iter().cloned().fold(f64::INFINITY, f64::min);
                for _ in 0..n {
                    let u = 2.0 * rng.uniform() - 1.0;
                    let a = std::f64::consts::TAU * rng.uniform();
                    let w = (1.0 - u * u).sqrt();
                    let dir = [w * a.cos(), w * a.sin(), u];
                    // Leaves: an exponential depth below the outer surface, none past the centre.
                    let r = (1.0 + depth * (1.0 - rng.uniform()).ln() / s[0].min(s[1]).min(s[2]))
                        .max(0.0);
                    let q = [0, 1, 2].map(|k| c[k] + r * s[k] * dir[k]);
                    if self.standing == Standing::Face && q[1] > 0.0 {
                        continue;
                    }
                    out.push(q);
                }
                if self.kind == PlantKind::Tree {
                    // The trunk: a cylinder of radius 0.15 m from the root to the crown.
                    let (r, h) = (0.15, c[2] - s[2] - self.root[2]);
                    let n = (std::f64::consts::TAU * r * h * density) as usize;
                    for _ in 0..n {
                        let a = std::f64::consts::TAU * rng.uniform();
                        let z = h * rng.uniform();
                        out.push([
                            self.root[0] + r * a.cos(),
                            self.root[1] + r * a.sin(),
                            self.root[2] + z,
                        ]);
                    }
                }
            }
            PlantKind::Tuft => {
                // Twelve blades from the root, leaning out, each a line of points a third of the
                // surfaces' spacing apart.
                let step = 1.0 / (3.0 * density.sqrt());
                for _ in 0..12 {
                    let lean = [
                        self.size[0] * (2.0 * rng.uniform() - 1.0),
                        self.size[1] * (2.0 * rng.uniform() - 1.0),
                    ];
                    let h = self.size[2] * (0.6 + 0.4 * rng.uniform());
                    let m = (h / step).ceil() as usize;
                    for k in 1..=m {
                        let t = k as f64 / m as f64;
                        out.push([
                            self.root[0] + lean[0] * t,
                            self.root[1] + lean[1] * t,
                            self.root[2] + h * t,
                        ]);
                    }
                }
            }
        }
        out
    }
}

/// Whether surface point `p` (local) is hidden by one of `plants` in epoch `epoch`: in a crown's
/// shadow, and chosen by a hash of its coordinates with probability [`HIDDEN`].
pub(crate) fn hidden(plants: &[Plant], p: &V3, seed: u64, epoch: u64) -> bool {
    if !plants.iter().any(|pl| pl.shadows(p)) {
        return false;
    }
    let mut h = seed ^ (epoch.wrapping_mul(0x9e37_79b9_7f4a_7c15));
    for v in p {
        h = talus_base::rng::SplitMix64::new(h ^ v.to_bits()).next_u64();
    }
    ((h >> 11) as f64 / (1u64 << 53) as f64) < HIDDEN
}
