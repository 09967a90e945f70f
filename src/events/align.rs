//! A rigid transform between two epochs fitted on their stable ground (SPEC.md §1
//! "Registration: removed, not only measured"): point-to-plane least squares (Chen & Medioni
//! 1992) over the stable core points and their M3C2 correspondences, linearised for small
//! rotations (Low 2004, "Linear least-squares optimization for point-to-plane ICP surface
//! registration", UNC TR04-004), with the stable set re-selected from the residuals as in
//! [`super::stable`].
//!
//! Model. Misregistration moves the later epoch by x ↦ R x + t. Along core point c's normal n
//! the M3C2 distance on ground that did not change is then d ≈ n·(t + ω × (c − o)) + e, ω the
//! small rotation vector about the stable ground's centroid o and e the noise: linear in the six
//! unknowns p = (ω, t), row a = ((c − o) × n, n). The rotation's columns are scaled by the stable
//! ground's RMS radius L, so that every unknown is a displacement in metres at that radius and
//! the normal matrix's eigenvalues compare.
//!
//! What the stable ground can see. A direction of the six whose eigenvalue is small (a flat
//! beach sees no horizontal shift and no turn about the vertical: its standard error would be
//! more than half the noise of one distance) is not constrained: the fit is the truncated pseudo-inverse (Golub & Van Loan §5.5.4), which
//! leaves such a direction at zero. It is **applied** only when (1) enough stable points, (2) the
//! vertical and both tilts at least are constrained, (3) the fitted motion is larger than its
//! own uncertainty (χ² of p over its covariance above the 99.9 % quantile of its degrees of
//! freedom), (4) the stable ground, the fit removed, holds still to within [`RIGID`] times its
//! measurement noise (a beach whose sand moved, or a slope creeping as a whole, does not: its
//! "fit" would be a tilt of the ground, not of the survey) and (5) it moves the stable surface
//! by at least a fifth of the noise of one M3C2 distance (a millimetre shift on a
//! centimetre-noise survey changes nothing worth the risk).
//! Otherwise it is reported with the reason, and not applied.

use nalgebra::{Matrix6, SymmetricEigen, Vector3, Vector6};

use super::stable::Sample;
use crate::geom::Point3;

/// Fewest stable points a fit is tried on.
pub const MIN_POINTS: usize = 200;
/// A direction of the scaled normal matrix whose eigenvalue is below this is not constrained:
/// its standard error, σ/√λ at the stable ground's radius, would be more than half the noise of
/// one distance (λ is the information of that many points entirely along it).
pub const CONSTRAINED: f64 = 4.0;
/// χ² of the fitted motion that makes it significant: the 99.9 % quantile, by degrees of
/// freedom (1 to 6).
const CHI2_999: [f64; 6] = [10.83, 13.82, 16.27, 18.47, 20.52, 22.46];
/// A motion moving the stable surface by less than this share of σ_d is not applied.
pub const MIN_EFFECT: f64 = 0.2;
/// After a fit, the stable ground must hold still to within this many times its measurement
/// noise (LoD95 / 1.96 of its distances): a misregistration is rigid, and removing it leaves the
/// surveys' noise; ground that moves (a beach, a creeping slope) leaves far more, and a "fit" to
/// it would be a tilt of the sand, not of the survey.
pub const RIGID: f64 = 3.0;
/// After a fit, at least this share of what the core points tell of every direction it
/// constrains well ([`WELL_SEEN`]) must come from ground at rest ([`Alignment::at_rest_share`]): ground that moves
/// is then a minority, and the stable ground the fit chose is the site's, not a self-selected
/// part of a moving slope.
pub const AT_REST: f64 = 0.5;
/// The at-rest share is judged on the directions the stable ground sees with at least this
/// share of the information of its best-seen one: a direction seen a thousand times less (a
/// shift along a straight coast, seen only through the side walls of an old scar) is fixed by a
/// few features, not by the ground at large, and what tells most of it is the walls of new
/// changes — a share there measures the changes, not whether the ground holds still.
pub const WELL_SEEN: f64 = 0.01;

/// The fitted transform of the later epoch, and what was decided.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Alignment {
    /// The rotation vector ω (radians, about `origin`) and translation t of the later epoch's
    /// misregistration: later ≈ R(ω)(x − o) + o + t.
    pub rotation: Point3,
    pub translation: Point3,
    pub origin: Point3,
    /// Standard errors of ω (radians) and t (metres); none for a component the stable ground
    /// does not constrain (the fit leaves it at zero: the survey is not moved that way).
    pub rotation_sd: [Option<f64>; 3],
    pub translation_sd: [Option<f64>; 3],
    /// Degrees of freedom the stable ground constrains (of 6).
    pub constrained: usize,
    /// RMS over the stable points of the displacement along their normals the fit explains.
    pub effect_m: f64,
    /// Robust standard deviation of the residuals after the fit.
    pub residual_m: f64,
    /// What the residual would be from the surveys' noise alone: the median over the stable
    /// points of LoD95 / 1.96, the standard error of one M3C2 distance from its cylinders'
    /// spreads and counts.
    pub noise_m: f64,
    pub chi2: f64,
    pub stable_points: usize,
    /// The least, over the directions the fit constrains well ([`WELL_SEEN`]), share of what
    /// the core points tell of that direction (Σ (a·v)² over the pool) that comes from core points the fit leaves at
    /// rest: near 1 when a misregistration was removed, small when the fit holds still only a
    /// self-selected part of ground that moves.
    pub at_rest_share: f64,
    pub applied: bool,
    /// The transform is known: enough stable ground, seeing the vertical and both tilts, that
    /// holds still as one rigid body, at rest, once it is removed (every rule of the module's
    /// header but the significance (3) and the effect (5)).
    /// A known transform that is not applied is known to be too small to matter: a chain of
    /// alignments may pass through it as the identity ([`super::chain`]); an unknown one it may not.
    pub determined: bool,
    /// Why it was, or was not, applied.
    pub reason: String,
}

impl Alignment {
    /// No fit (`reason` says why): the identity, not applied.
    pub fn none(reason: String) -> Alignment {
        Alignment {
            rotation: [0.0; 3],
            translation: [0.0; 3],
            origin: [0.0; 3],
            rotation_sd: [None; 3],
            translation_sd: [None; 3],
            constrained: 0,
            effect_m: 0.0,
            residual_m: 0.0,
            noise_m: 0.0,
            chi2: 0.0,
            stable_points: 0,
            at_rest_share: 0.0,
            applied: false,
            determined: false,
            reason,
        }
    }

    /// The 4×4 matrix (row-major) mapping the later epoch's coordinates onto the earlier's: the
    /// inverse of the misregistration, with the exact rotation of ω (Rodrigues).
    pub fn matrix(&self) -> [[f64; 4]; 4] {
        let r = rotation(&self.rotation);
        let rt = r.transpose();
        let o = Vector3::from(self.origin);
        let t = Vector3::from(self.translation);
        // x_earlier = Rᵀ (x_later − o − t) + o
        let shift = o - rt * (o + t);
        let mut m = [[0.0; 4]; 4];
        for i in 0..3 {
            for j in 0..3 {
                m[i][j] = rt[(i, j)];
            }
            m[i][3] = shift[i];
        }
        m[3][3] = 1.0;
        m
    }

    /// `p` (later epoch) mapped onto the earlier epoch.
    pub fn apply(&self, p: &Point3) -> Point3 {
        let m = self.matrix();
        let mut out = [0.0; 3];
        for (i, o) in out.iter_mut().enumerate() {
            *o = m[i][0] * p[0] + m[i][1] * p[1] + m[i][2] * p[2] + m[i][3];
        }
        out
    }

    /// The rotation's angle in degrees.
    pub fn rotation_deg(&self) -> f64 {
        Vector3::from(self.rotation).norm().to_degrees()
    }
}

/// The rotation matrix of rotation vector `w` (Rodrigues' formula).
fn rotation(w: &Point3) -> nalgebra::Matrix3<f64> {
    let w = Vector3::from(*w);
    let angle = w.norm();
    if angle == 0.0 {
        return nalgebra::Matrix3::identity();
    }
    nalgebra::Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(w), angle).into_inner()
}

/// The least, over the kept eigen-directions `kept` of `eig`, share of the pool's information
/// about that direction (Σ (a·v)², a the model's rows) carried by the core points `rests` says are
/// at rest, over the kept directions seen with at least [`WELL_SEEN`] of the best-seen one's
/// information. The rows are those of the fit (same origin and scale as the
/// eigen-decomposition); NaN with no kept direction.
fn at_rest_share(
    pool: &[usize],
    kept: &[usize],
    eig: &SymmetricEigen<f64, nalgebra::U6>,
    rows: impl Fn(usize) -> Vector6<f64>,
    rests: impl Fn(usize) -> bool,
) -> f64 {
    let top = kept.iter().map(|&k| eig.eigenvalues[k]).fold(0.0, f64::max);
    let kept: Vec<usize> = kept
        .iter()
        .copied()
        .filter(|&k| eig.eigenvalues[k] >= WELL_SEEN * top)
        .collect();
    // One pass over the pool: each row and its rest computed once, its weight along every kept
    // direction summed.
    let (mut all, mut still) = (vec![0.0; kept.len()], vec![0.0; kept.len()]);
    for &i in pool {
        let (a, at_rest) = (rows(i), rests(i));
        for (j, &k) in kept.iter().enumerate() {
            let w = a.dot(&eig.eigenvectors.column(k)).powi(2);
            all[j] += w;
            if at_rest {
                still[j] += w;
            }
        }
    }
    still
        .iter()
        .zip(&all)
        .map(|(s, a)| s / a)
        .fold(f64::NAN, |least, share| {
            if least.is_nan() || share < least {
                share
            } else {
                least
            }
        })
}

/// The model's row of sample `s` about `o`, rotation columns scaled by `scale`.
fn row(s: &Sample, o: &Vector3<f64>, scale: f64) -> Vector6<f64> {
    let n = Vector3::from(s.normal);
    let c = Vector3::from(s.xyz) - o;
    let r = c.cross(&n) / scale;
    Vector6::new(r[0], r[1], r[2], n[0], n[1], n[2])
}

/// The median of `v` (NaN-free), reordering it.
fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    let k = v.len() / 2;
    let (_, m, _) = v.select_nth_unstable_by(k, |a, b| a.total_cmp(b));
    *m
}

/// A least-squares solution over `idx` with the truncated pseudo-inverse; returns the scaled
/// parameters, the eigen-decomposition of the normal matrix and the kept directions.
fn solve(
    samples: &[Sample],
    idx: &[usize],
    o: &Vector3<f64>,
    scale: f64,
) -> (Vector6<f64>, SymmetricEigen<f64, nalgebra::U6>, Vec<usize>) {
    let mut n = Matrix6::zeros();
    let mut b = Vector6::zeros();
    for &i in idx {
        let a = row(&samples[i], o, scale);
        n += a * a.transpose();
        b += a * samples[i].distance;
    }
    let eig = SymmetricEigen::new(n);
    let top = eig.eigenvalues.iter().cloned().fold(0.0, f64::max);
    // Also far above the rounding of the largest (a direction exactly unseen is 0 ± that).
    let kept: Vec<usize> = (0..6)
        .filter(|&k| eig.eigenvalues[k] >= CONSTRAINED.max(1e-9 * top))
        .collect();
    let mut p = Vector6::zeros();
    for &k in &kept {
        let v = eig.eigenvectors.column(k);
        p += v * (v.dot(&b) / eig.eigenvalues[k]);
    }
    (p, eig, kept)
}

/// Fit the misregistration starting from `stable` (indices into `samples`, their M3C2 distances
/// finite), then re-selecting the stable ground among `pool` by the rigid model's residuals:
/// within [`super::stable::KEEP_SIGMAS`] robust standard deviations. (The stable set a
/// translation alone finds leaves out what a turn moves more than the noise — the far ends of a
/// wall turned 0.1° about the vertical — and a fit on what is left would be biased toward no
/// turn.) `sigma_d` is the noise of one distance on stable ground.
pub fn fit(samples: &[Sample], stable: &[usize], pool: &[usize], sigma_d: f64) -> Alignment {
    let mut keep: Vec<usize> = stable.to_vec();
    let centroid = |idx: &[usize]| -> Vector3<f64> {
        let mut s = Vector3::zeros();
        for &i in idx {
            s += Vector3::from(samples[i].xyz);
        }
        s / idx.len().max(1) as f64
    };
    let o = centroid(&keep);
    let scale = (keep
        .iter()
        .map(|&i| (Vector3::from(samples[i].xyz) - o).norm_squared())
        .sum::<f64>()
        / keep.len().max(1) as f64)
        .sqrt()
        .max(1e-9);
    let residual =
        |p: &Vector6<f64>, i: usize| samples[i].distance - row(&samples[i], &o, scale).dot(p);
    let mut fitted = solve(samples, &keep, &o, scale);
    // Graduated re-selection (the shrinking distance threshold of ICP): the pool's points join
    // within a radius that starts at twice their median residual after the first fit — so a
    // part of the stable ground the first set left out (a beach tilted by a turn the wall it
    // started from cannot see) is taken in — and halves each round down to KEEP_SIGMAS robust
    // standard deviations, which leaves the changed ground out again.
    let mut all: Vec<f64> = pool.iter().map(|&i| residual(&fitted.0, i).abs()).collect();
    let mut radius = 2.0 * median(&mut all);
    let mut sigma = f64::NAN;
    for _ in 0..24 {
        if keep.len() < MIN_POINTS {
            break;
        }
        let mut dev: Vec<f64> = keep.iter().map(|&i| residual(&fitted.0, i).abs()).collect();
        sigma = 1.4826 * median(&mut dev);
        let floor = super::stable::KEEP_SIGMAS * sigma;
        let within = radius.max(floor);
        let next: Vec<usize> = pool
            .iter()
            .copied()
            .filter(|&i| residual(&fitted.0, i).abs() <= within)
            .collect();
        radius /= 2.0;
        if next.len() < MIN_POINTS {
            break;
        }
        if next == keep && within <= floor {
            break;
        }
        keep = next;
        fitted = solve(samples, &keep, &o, scale);
    }
    let (p, eig, kept) = fitted;
    let mut dev: Vec<f64> = keep.iter().map(|&i| residual(&p, i).abs()).collect();
    if !dev.is_empty() {
        sigma = 1.4826 * median(&mut dev);
    }
    let mut lods: Vec<f64> = keep
        .iter()
        .map(|&i| samples[i].lod / 1.96)
        .filter(|l| l.is_finite())
        .collect();
    let noise = median(&mut lods);
    // Covariance of the kept directions: σ² Σ v vᵀ / λ.
    let var = sigma * sigma;
    let mut cov = Matrix6::zeros();
    let mut chi2 = 0.0;
    for &k in &kept {
        let v = eig.eigenvectors.column(k);
        cov += v * v.transpose() * (var / eig.eigenvalues[k]);
        let along = v.dot(&p);
        chi2 += along * along * eig.eigenvalues[k] / var.max(f64::MIN_POSITIVE);
    }
    let effect = (keep
        .iter()
        .map(|&i| row(&samples[i], &o, scale).dot(&p).powi(2))
        .sum::<f64>()
        / keep.len().max(1) as f64)
        .sqrt();
    // A parameter with a part in an unconstrained direction has no standard error.
    let free = |k: usize| -> f64 {
        (0..6)
            .filter(|j| !kept.contains(j))
            .map(|j| eig.eigenvectors[(k, j)].powi(2))
            .sum()
    };
    let sd = |k: usize, unit: f64| (free(k) < 1e-3).then(|| cov[(k, k)].max(0.0).sqrt() / unit);
    // Vertical and both tilts: the unit vertical translation and the horizontal rotations.
    let sees = |dir: Vector6<f64>| -> bool {
        let dir = dir.normalize();
        let seen: f64 = kept
            .iter()
            .map(|&k| eig.eigenvectors.column(k).dot(&dir).powi(2))
            .sum();
        seen > 0.99
    };
    let vertical = sees(Vector6::new(0.0, 0.0, 0.0, 0.0, 0.0, 1.0))
        && sees(Vector6::new(1.0, 0.0, 0.0, 0.0, 0.0, 0.0))
        && sees(Vector6::new(0.0, 1.0, 0.0, 0.0, 0.0, 0.0));
    let dof = kept.len();
    let at_rest = at_rest_share(
        pool,
        &kept,
        &eig,
        |i| row(&samples[i], &o, scale),
        |i| residual(&p, i).abs() <= super::stable::KEEP_SIGMAS * sigma.max(noise),
    );
    let (applied, determined, reason) = decide(&Figures {
        stable: keep.len(),
        vertical,
        dof,
        chi2,
        sigma,
        noise,
        at_rest,
        effect,
        sigma_d,
    });
    Alignment {
        rotation: [p[0] / scale, p[1] / scale, p[2] / scale],
        translation: [p[3], p[4], p[5]],
        origin: [o[0], o[1], o[2]],
        rotation_sd: [sd(0, scale), sd(1, scale), sd(2, scale)],
        translation_sd: [sd(3, 1.0), sd(4, 1.0), sd(5, 1.0)],
        constrained: dof,
        effect_m: effect,
        residual_m: sigma,
        noise_m: noise,
        chi2,
        stable_points: keep.len(),
        at_rest_share: at_rest,
        applied,
        determined,
        reason,
    }
}

/// What [`fit`] measured, for [`decide`].
struct Figures {
    stable: usize,
    vertical: bool,
    dof: usize,
    chi2: f64,
    sigma: f64,
    noise: f64,
    at_rest: f64,
    effect: f64,
    sigma_d: f64,
}

/// Whether a fit is applied, whether it is determined ([`Alignment::determined`]), and why (or
/// why not): the rules of the module's header, in order.
fn decide(f: &Figures) -> (bool, bool, String) {
    let &Figures {
        stable,
        vertical,
        dof,
        chi2,
        sigma,
        noise,
        at_rest,
        effect,
        sigma_d,
    } = f;
    let rigid = !(sigma.is_nan() || noise.is_nan() || sigma > RIGID * noise);
    let at_rest_ok = !(at_rest.is_nan() || at_rest < AT_REST);
    let determined = stable >= MIN_POINTS && vertical && rigid && at_rest_ok;
    let not = if stable < MIN_POINTS {
        format!(
            "not applied: {} stable core points, fewer than {MIN_POINTS}",
            stable
        )
    } else if !vertical {
        format!(
            "not applied: the stable ground constrains {dof} of 6 directions, not the vertical \
             and both tilts"
        )
    } else if chi2 <= CHI2_999[dof.clamp(1, 6) - 1] {
        format!(
            "not applied: the motion is within its own uncertainty (χ² {chi2:.1} over {dof} \
             directions, 99.9 % quantile {:.1})",
            CHI2_999[dof.clamp(1, 6) - 1]
        )
    } else if !rigid {
        format!(
            "not applied: the stable ground does not hold still as one rigid body: after the \
             fit its distances spread by {sigma:.4} (robust standard deviation), {:.1} × the \
             noise of one distance ({noise:.4}); ground that moves (sand, a slow landslide) is not \
             a misregistration",
            sigma / noise
        )
    } else if !at_rest_ok {
        format!(
            "not applied: after the fit only {:.0} % of the ground that fixes its least-seen \
             direction is at rest (a misregistration removed leaves all stable ground at rest \
             but for a few changes): the ground moves, by different amounts in different places \
             (a settling slope, sand), and the fit held still only the places that happen to \
             agree",
            100.0 * at_rest
        )
    } else if effect.is_nan() || sigma_d.is_nan() || effect < MIN_EFFECT * sigma_d {
        format!(
            "not applied: it moves the stable surface by {:.4} (RMS along the normals), less \
             than {MIN_EFFECT} × σ_d ({:.4})",
            effect, sigma_d
        )
    } else {
        return (
            true,
            true,
            format!(
                "applied: {dof} of 6 directions constrained by {stable} stable core points; it \
                 moves them by {effect:.4} (RMS along the normals), χ² {chi2:.0}"
            ),
        );
    };
    (false, determined, not)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;

    /// Core points on three faces of a block (a floor, two walls) — or on the floor alone —
    /// with M3C2 distances of the later epoch moved by (ω about `o`, t), plus noise `noise`.
    fn scene(
        w: Point3,
        t: Point3,
        o: Point3,
        noise: f64,
        floor_only: bool,
        seed: u64,
    ) -> Vec<Sample> {
        let mut r = SplitMix64::new(seed);
        let mut out = Vec::new();
        for k in 0..3000 {
            let face = if floor_only { 0 } else { k % 3 };
            let (a, b) = (r.range(0.0, 40.0), r.range(0.0, 20.0));
            let (xyz, normal) = match face {
                0 => ([a, b, 0.0], [0.0, 0.0, 1.0]),
                1 => ([a, 0.0, b], [0.0, -1.0, 0.0]),
                _ => ([0.0, a / 2.0, b], [-1.0, 0.0, 0.0]),
            };
            let c = Vector3::from(xyz) - Vector3::from(o);
            let moved = Vector3::from(w).cross(&c) + Vector3::from(t);
            let d = Vector3::from(normal).dot(&moved) + noise * r.normal();
            out.push(Sample {
                xyz,
                normal,
                distance: d,
                std_dev: [noise, noise],
                lod: 2.0 * noise,
            });
        }
        out
    }

    fn all(s: &[Sample]) -> Vec<usize> {
        (0..s.len()).collect()
    }

    #[test]
    fn a_shift_and_a_turn_are_recovered_within_their_uncertainty() {
        let w = [0.0005, -0.0003, 0.002]; // 0.03°, 0.02°, 0.11°
        let t = [0.06, -0.04, 0.08];
        let s = scene(w, t, [10.0, 5.0, 3.0], 0.01, false, 1);
        let a = fit(&s, &all(&s), &all(&s), 0.01);
        assert!(a.applied, "{}", a.reason);
        assert_eq!(a.constrained, 6);
        // The fit's own origin: ω is the same, t moves by ω × (o − o_fit).
        let shift =
            Vector3::from(w).cross(&(Vector3::from(a.origin) - Vector3::from([10.0, 5.0, 3.0])));
        for k in 0..3 {
            let want_t = t[k] + shift[k];
            let (ws, ts) = (a.rotation_sd[k].unwrap(), a.translation_sd[k].unwrap());
            assert!(
                (a.rotation[k] - w[k]).abs() <= 4.0 * ws + 1e-12,
                "ω{k} {} vs {} ± {ws}",
                a.rotation[k],
                w[k],
            );
            assert!(
                (a.translation[k] - want_t).abs() <= 4.0 * ts + 1e-12,
                "t{k} {} vs {want_t} ± {ts}",
                a.translation[k],
            );
        }
        assert!((a.residual_m - 0.01).abs() < 0.002, "{}", a.residual_m);
        // Mapping a moved point back lands on the original.
        let p = [20.0, 7.0, 4.0];
        let c = Vector3::from(p) - Vector3::from(a.origin);
        let moved =
            Vector3::from(p) + Vector3::from(a.rotation).cross(&c) + Vector3::from(a.translation);
        let back = a.apply(&[moved[0], moved[1], moved[2]]);
        for k in 0..3 {
            assert!((back[k] - p[k]).abs() < 1e-3, "{back:?} vs {p:?}");
        }
    }

    #[test]
    fn registered_surveys_are_not_aligned() {
        let s = scene([0.0; 3], [0.0; 3], [0.0; 3], 0.01, false, 2);
        let a = fit(&s, &all(&s), &all(&s), 0.01);
        assert!(!a.applied, "{}", a.reason);
        assert!(a.reason.contains("uncertainty"), "{}", a.reason);
    }

    #[test]
    fn flat_ground_constrains_only_the_vertical_and_the_tilts() {
        let s = scene([0.001, 0.0, 0.0], [0.3, 0.0, 0.05], [0.0; 3], 0.01, true, 3);
        let a = fit(&s, &all(&s), &all(&s), 0.01);
        assert_eq!(a.constrained, 3, "{a:?}");
        // The horizontal shift is invisible: left at zero, not guessed, and said so.
        assert!(a.translation[0].abs() < 1e-6, "{a:?}");
        assert_eq!(a.translation_sd[0], None);
        assert_eq!(a.rotation_sd[2], None);
        assert!(a.translation_sd[2].is_some() && a.rotation_sd[0].is_some());
        assert!(a.applied, "{}", a.reason);
    }

    #[test]
    fn a_wall_alone_is_not_enough() {
        let mut s = scene([0.0; 3], [0.05, 0.0, 0.0], [0.0; 3], 0.01, false, 4);
        // Keep the wall facing −x only.
        s.retain(|p| p.normal[0] != 0.0);
        let a = fit(&s, &all(&s), &all(&s), 0.01);
        assert!(!a.applied);
        assert!(a.reason.contains("directions"), "{}", a.reason);
    }

    #[test]
    fn changed_points_among_the_stable_ones_are_left_out() {
        let w = [0.0, 0.0, 0.001];
        let t = [0.02, 0.03, -0.05];
        let mut s = scene(w, t, [0.0; 3], 0.01, false, 5);
        // A tenth of them changed by a metre.
        for p in s.iter_mut().step_by(10) {
            p.distance += 1.0;
        }
        let a = fit(&s, &all(&s), &all(&s), 0.01);
        assert!(a.applied, "{}", a.reason);
        assert!(a.stable_points < 2800, "{}", a.stable_points);
        assert!((a.residual_m - 0.01).abs() < 0.003, "{}", a.residual_m);
        assert!(a.at_rest_share > 0.8, "{}", a.at_rest_share);
    }

    #[test]
    fn a_floor_settling_by_different_amounts_is_not_a_misregistration() {
        // The walls stand still (a vertical wall shows no settling); the floor sinks by 2.5 to
        // 10 cm, varying smoothly. A fit can hold still the floor's places whose settling
        // happens to agree — the residual is the noise — but most of what fixes the vertical is
        // floor that moved.
        let mut s = scene([0.0; 3], [0.0; 3], [0.0; 3], 0.002, false, 6);
        let k = 2.0 * std::f64::consts::PI / 24.0;
        for p in s.iter_mut().filter(|p| p.normal[2] != 0.0) {
            let share = 0.625 + 0.375 * (k * p.xyz[0]).sin() * (k * p.xyz[1]).cos();
            p.distance -= 0.1 * share;
        }
        // The walls, and the floor's places that settled by the mean (the cliff's sample had
        // such: 26 of its first stable set's 22,935 points faced up).
        let first: Vec<usize> = (0..s.len())
            .filter(|&i| s[i].normal[2] == 0.0 || (s[i].distance + 0.0625).abs() < 0.002)
            .collect();
        let a = fit(&s, &first, &all(&s), 0.002);
        assert!(!a.applied, "{a:?}");
        assert!(a.at_rest_share < 0.5, "{a:?}");
        assert!(a.reason.contains("at rest"), "{}", a.reason);
    }
}
