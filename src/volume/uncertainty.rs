//! The uncertainty of an event's volume: a propagated 95 % half-width (SPEC.md §1 "Volume
//! accounting"), as geomorphic change detection does for a DEM of difference (Wheaton et al. 2010,
//! ESPL 35:136; Anderson 2019, ESPL 44:1015), with three independent parts:
//!
//! - **random**: each surface is a TIN, whose integral over the region is Σᵢ zᵢ aᵢ with aᵢ the
//!   area a vertex carries (one point's share, s² = region area / points in it). With independent
//!   vertex errors of variance σ² the integral's variance is Σ aᵢ² σᵢ² = A s² σ̄² per epoch: the
//!   averaging over A / s² points is what makes it small. σ̄² is the mean per-point spread over the
//!   region (M3C2's standard deviation of the points along the normal: measurement noise, and
//!   where the surface steps within a cylinder, the step, which a TIN only samples);
//! - **spatially correlated**: errors that vary smoothly over the site (SfM doming, strip
//!   misalignment) do not average out within their range. With the covariance C(h) of the
//!   stable ground's variogram ([`crate::events::stable`]), the error of the mean over the
//!   region has variance (1/A²)∬ C(|x − y|) dx dy over the region's own shape, estimated from
//!   pairs of random locations in its cells (a fixed-seed generator: deterministic); for a region
//!   much larger than the range it tends to σ_c² π a² / (5 A) (Rolstad et al. 2009, J. Glaciol.
//!   55:666), which is used there directly;
//! - **systematic**: a registration error between the epochs moves the whole surface by the same
//!   amount, so it is fully correlated over the event: A × the displacement along the event's
//!   axis.
//!
//! - **sampling of steps**: a TIN places a step (a scar's side, a block's edge) anywhere between
//!   the points either side of it, an error of the step's height × its length × up to half a
//!   spacing that no averaging removes ([`Region::step_variance`]); it matters where the
//!   spacing is coarse against the event (a 2 m box sampled every 0.26 m).
//!
//! The half-width is 1.96 × √(random² + correlated² + systematic² + sampling²).

use super::region::Region;
use crate::events::stable::Variogram;

/// Random location pairs for the correlated part's mean covariance.
const PAIRS: usize = 100_000;
/// Regions larger than this many times π a² take Rolstad's large-area form.
const LARGE: f64 = 50.0;

/// The parts of an event's volume uncertainty (one standard deviation each, m³) and the 95 %
/// half-width.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub(crate) struct VolumeUncertainty {
    pub(crate) random_m3: f64,
    pub(crate) correlated_m3: f64,
    pub(crate) systematic_m3: f64,
    #[serde(default)]
    pub(crate) sampling_m3: f64,
    /// 1.96 × the combined standard deviation.
    pub(crate) half_width_95_m3: f64,
}

/// What the propagation needs of one event.
#[derive(Debug, Clone, Copy)]
pub(crate) struct ErrorModel {
    /// Per epoch: region area per point (s², m²).
    pub(crate) point_area: [f64; 2],
    /// Per epoch: mean per-point variance over the region (m²).
    pub(crate) variance: [f64; 2],
    /// The stable ground's variogram, if measured.
    pub(crate) variogram: Option<Variogram>,
    /// The registration error along the event's axis (m).
    pub(crate) systematic: f64,
    /// The standard deviation of the volume from the sampling of its steps (m³).
    pub(crate) sampling: f64,
}

/// Propagate `model` over `region`.
pub(crate) fn propagate(region: &Region, model: &ErrorModel) -> VolumeUncertainty {
    let a = region.area();
    let random = (0..2)
        .map(|k| a * model.point_area[k] * model.variance[k])
        .filter(|v| v.is_finite() && *v > 0.0)
        .sum::<f64>()
        .sqrt();
    let correlated = match model.variogram {
        Some(v) if v.sill > 0.0 => a * mean_covariance(region, &v).sqrt(),
        _ => 0.0,
    };
    let systematic = a * model.systematic.abs();
    let sampling = if model.sampling.is_finite() {
        model.sampling.abs()
    } else {
        0.0
    };
    let total =
        (random * random + correlated * correlated + systematic * systematic + sampling * sampling)
            .sqrt();
    VolumeUncertainty {
        random_m3: random,
        correlated_m3: correlated,
        systematic_m3: systematic,
        sampling_m3: sampling,
        half_width_95_m3: 1.96 * total,
    }
}

/// Mean covariance between two locations of the region: the mean of C over pairs of random
/// locations (a random cell of the region, a random point in it), or σ_c² π a² / (5 A) for a
/// region much larger than the range.
fn mean_covariance(region: &Region, v: &Variogram) -> f64 {
    let area = region.area();
    let disc = std::f64::consts::PI * v.range * v.range;
    if area > LARGE * disc {
        return v.sill * disc / (5.0 * area);
    }
    let c = &region.cells;
    let cells: Vec<(usize, usize)> = (0..c.nv)
        .flat_map(|j| (0..c.nu).map(move |i| (i, j)))
        .filter(|&(i, j)| region.contains(i, j))
        .collect();
    if cells.is_empty() {
        return 0.0;
    }
    let (du, dv) = (
        (c.r.u1 - c.r.u0) / c.nu as f64,
        (c.r.v1 - c.r.v0) / c.nv as f64,
    );
    // A fixed seed: the same event gets the same locations in every run.
    let mut rng = crate::rng::SplitMix64::new(0x9E37_79B9_7F4A_7C15u64 ^ cells.len() as u64);
    let mut next = || rng.next_u64();
    let mut location = || {
        let (i, j) = cells[(next() % cells.len() as u64) as usize];
        let f = |x: u64| (x >> 11) as f64 / (1u64 << 53) as f64;
        [c.u(i) + du * f(next()), c.v(j) + dv * f(next())]
    };
    let mut sum = 0.0;
    for _ in 0..PAIRS {
        let (p, q) = (location(), location());
        // sqrt of the squares, not hypot: no overflow is possible at these lags, and libm's
        // correctly rounded hypot was 6 % of the volumes stage (10⁵ pairs an event).
        let (du, dv) = (p[0] - q[0], p[1] - q[1]);
        sum += v.covariance((du * du + dv * dv).sqrt());
    }
    sum / PAIRS as f64
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::volume::frame::Footprint;
    use crate::volume::region::Cells;

    fn square(side: f64, cell: f64) -> Region {
        let r = Footprint {
            u0: 0.0,
            u1: side,
            v0: 0.0,
            v1: side,
        };
        let cells = Cells::new(&r, cell);
        let all = vec![true; cells.len()];
        Region::new(cells, all.clone(), &all)
    }

    #[test]
    fn random_part_averages_over_the_points() {
        let region = square(10.0, 0.5);
        let u = propagate(
            &region,
            &ErrorModel {
                point_area: [0.01, 0.01],
                variance: [1e-4, 1e-4],
                variogram: None,
                systematic: 0.0,
                sampling: 0.0,
            },
        );
        // √(2 × 100 m² × 0.01 m² × 1e-4 m²) = 0.01414 m³.
        assert!((u.random_m3 - 0.014142).abs() < 1e-5, "{u:?}");
        assert!((u.half_width_95_m3 - 1.96 * u.random_m3).abs() < 1e-12);
    }

    /// A straight step of height H across a square, sampled every s: H²s⁴/12 per length s of
    /// step (the step's place uniform within ±s/2); a plane gives nothing.
    #[test]
    fn a_step_carries_its_sampling_variance_and_a_plane_none() {
        let (side, s, h) = (4.0, 0.1, 0.7);
        let region = square(side, s);
        // The after surface's heights at the cells' centres over a flat before surface.
        let c = region.cells;
        let at_centres = |f: &dyn Fn(f64, f64) -> f64| -> Vec<f64> {
            (0..c.nv)
                .flat_map(|j| (0..c.nu).map(move |i| c.centre(i, j)))
                .map(|[u, v]| f(u, v))
                .collect()
        };
        let flat = vec![0.0; c.len()];
        let step = at_centres(&|u, _v| if u < 2.05 { 0.0 } else { -h });
        let want = (side / s) * h * h * s.powi(4) / 12.0;
        let got = region.step_variance(&region.cell_changes(&flat, &step), s);
        assert!((got - want).abs() < 1e-9 * want, "{got} vs {want}");
        let plane = at_centres(&|u, v| 0.3 * u - 0.2 * v + 1.0);
        assert!(region.step_variance(&region.cell_changes(&flat, &plane), s) < 1e-12 * want);
    }

    #[test]
    fn systematic_part_is_area_times_displacement() {
        let region = square(4.0, 0.5);
        let u = propagate(
            &region,
            &ErrorModel {
                point_area: [0.0; 2],
                variance: [0.0; 2],
                variogram: None,
                systematic: 0.02,
                sampling: 0.0,
            },
        );
        assert!((u.systematic_m3 - 0.32).abs() < 1e-12);
    }

    #[test]
    fn correlated_part_follows_rolstad_for_large_areas_and_is_full_for_small_ones() {
        let v = Variogram {
            nugget: 0.0,
            sill: 1e-4,
            range: 5.0,
        };
        let model = ErrorModel {
            point_area: [0.0; 2],
            variance: [0.0; 2],
            variogram: Some(v),
            systematic: 0.0,
            sampling: 0.0,
        };
        // Small against the range: nearly fully correlated, A × σ_c.
        let small = square(0.5, 0.05);
        let u = propagate(&small, &model);
        assert!(u.correlated_m3 > 0.9 * 0.25 * 0.01, "{u:?}");
        // Large: A σ_c √(π a² / 5A); at 40 × π a² (pairs sampled) less the square's edges,
        // where locations have fewer neighbours within the range.
        let large = square(56.0, 0.5);
        let u = propagate(&large, &model);
        let a = 56.0 * 56.0;
        let want = a * 0.01 * (std::f64::consts::PI * 25.0 / (5.0 * a)).sqrt();
        assert!(
            u.correlated_m3 < want && u.correlated_m3 > 0.85 * want,
            "{} vs {want}",
            u.correlated_m3
        );
    }
}
