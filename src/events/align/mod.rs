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
//! more than half the noise of one distance) is not constrained: the fit is the truncated
//! pseudo-inverse (Golub & Van Loan §5.5.4), which leaves such a direction at zero. Where the
//! vertical is seen but not both tilts (a single strip of stable ground), the fit is the
//! vertical shift alone: the bias DEM-of-difference practice removes on stable ground.
//!
//! It is **applied** only when, in order (`decide`): (1) enough stable points for the
//! directions fitted, (2) the vertical at least is constrained, (3) the fitted motion is larger
//! than its own uncertainty (χ² of p over its covariance above the 99.9 % quantile of its
//! degrees of freedom), (4) the stable ground, the fit removed, holds still to within [`RIGID`]
//! times its measurement noise (a beach whose sand moved, or a slope creeping as a whole, does
//! not: its "fit" would be a tilt of the ground, not of the survey), (5) ground at rest is most
//! of what fixes it ([`AT_REST`]), (6) it moves the stable surface by at least a fifth of the
//! noise of one M3C2 distance (a millimetre shift on a centimetre-noise survey changes nothing
//! worth the risk), (7) it holds out of sample: fitted on the stable ground of all but one block
//! of the footprint, it explains the held-out block's distances ([`holdout`]; change aligned
//! away explains nothing there), (8) it tilts the survey by no more than a levelled survey is
//! off (a tilt of degrees is change fitted, or a distorted surface: the BMX track of the autzen
//! pair, built up between surveys, "fits" a 6.7° turn), and (9) it is a plausible
//! misregistration ([`Limits`]: what GNSS, targets and ICP leave). A transform that passes all
//! but (9) is a gross misregistration ([`Alignment::gross`]): the surveys are far off, and the
//! caller says so.
//! Otherwise it is reported with the reason, and not applied.

use nalgebra::{Matrix6, SymmetricEigen, Vector3, Vector6};

use super::stable::{median, Sample};
use crate::geom::Point3;

pub(crate) mod holdout;

/// Fewest stable points a fit of `dof` directions is tried on: 30 a direction, at least 50.
pub(crate) fn min_points(dof: usize) -> usize {
    (30 * dof).max(50)
}
/// Fewest stable points the six-direction fit starts from.
pub(crate) const MIN_POINTS: usize = 180;
/// Least share of its predicted change the held-out ground must confirm ([`holdout`]), and
/// 2 − it the most: the share is 2β − 1 for β the slope of the held-out distances on the
/// prediction, 1 for one motion; a share far above 1 is structure the prediction only follows
/// (the tails of a mound that grew read as a tilt).
pub(crate) const HOLDS_OUT: f64 = 0.5;

/// How far a transform may move a survey and still be a misregistration (SPEC.md §1: "bounded by
/// what GNSS, targets and ICP leave"): the largest displacement it gives any point of the
/// stable ground's footprint, and its turn.
///
/// The default, [`Limits::PLAUSIBLE`] (1 m, 0.5°): airborne lidar strips adjusted to GNSS/INS
/// leave centimetres to a few decimetres (ASPRS 2014 positional accuracy standards: 10 cm RMSE
/// vertical at QL2, decimetres horizontal at common flying heights), UAV photogrammetry with
/// control points or RTK a few centimetres to two decimetres and tilts of hundredths to a few
/// tenths of a degree (poor control geometry), terrestrial scans registered to targets
/// millimetres to centimetres and hundredths of a degree. Twice the worst of these is the
/// bound; beyond it a "fit" is a different survey datum, a wrong CRS or change aligned away.
/// `--align on` raises it to [`Limits::FORCED`].
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub(crate) struct Limits {
    pub(crate) shift_m: f64,
    pub(crate) turn_deg: f64,
}

/// Whose stable ground a fit is on: found in the distances, or the user's areas. The user's
/// word makes their ground stable (as in DoD practice): a fit on it need not be confirmed on
/// held-out ground, which only says how much the areas agree among themselves.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Ground {
    Automatic,
    User,
}

impl Limits {
    pub(crate) const PLAUSIBLE: Limits = Limits {
        shift_m: 1.0,
        turn_deg: 0.5,
    };
    pub(crate) const FORCED: Limits = Limits {
        shift_m: 100.0,
        turn_deg: 20.0,
    };

    /// Whether a motion moving no point more than `largest` metres and turning `turn` degrees
    /// is within these.
    pub(crate) fn admit(&self, largest: f64, turn: f64) -> bool {
        largest <= self.shift_m && turn <= self.turn_deg
    }

    /// The limits between two surveys each within these of a third (a campaign's survey and its
    /// predecessor, both off the first): their offsets add up to twice.
    pub(crate) fn between(&self) -> Limits {
        Limits {
            shift_m: 2.0 * self.shift_m,
            turn_deg: 2.0 * self.turn_deg,
        }
    }
}
/// A direction of the scaled normal matrix whose eigenvalue is below this is not constrained:
/// its standard error, σ/√λ at the stable ground's radius, would be more than half the noise of
/// one distance (λ is the information of that many points entirely along it).
pub(crate) const CONSTRAINED: f64 = 4.0;
/// χ² of the fitted motion that makes it significant: the 99.9 % quantile, by degrees of
/// freedom (1 to 6).
const CHI2_999: [f64; 6] = [10.83, 13.82, 16.27, 18.47, 20.52, 22.46];
/// A motion moving the stable surface by less than this share of σ_d is not applied.
pub(crate) const MIN_EFFECT: f64 = 0.2;
/// After a fit, the stable ground must hold still to within this many times its measurement
/// noise (LoD95 / 1.96 of its distances): a misregistration is rigid, and removing it leaves the
/// surveys' noise; ground that moves (a beach, a creeping slope) leaves far more, and a "fit" to
/// it would be a tilt of the sand, not of the survey.
pub(crate) const RIGID: f64 = 3.0;
/// After a fit, at least this share of what the core points tell of every direction it
/// constrains well ([`WELL_SEEN`]) must come from ground at rest ([`Alignment::at_rest_share`]): ground that moves
/// is then a minority, and the stable ground the fit chose is the site's, not a self-selected
/// part of a moving slope.
pub(crate) const AT_REST: f64 = 0.5;
/// The at-rest share is judged on the directions the stable ground sees with at least this
/// share of the information of its best-seen one: a direction seen a thousand times less (a
/// shift along a straight coast, seen only through the side walls of an old scar) is fixed by a
/// few features, not by the ground at large, and what tells most of it is the walls of new
/// changes — a share there measures the changes, not whether the ground holds still.
pub(crate) const WELL_SEEN: f64 = 0.01;

/// The fitted transform of the later epoch, and what was decided.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub(crate) struct Alignment {
    /// The rotation vector ω (radians, about `origin`) and translation t of the later epoch's
    /// misregistration: later ≈ R(ω)(x − o) + o + t.
    pub(crate) rotation: Point3,
    pub(crate) translation: Point3,
    pub(crate) origin: Point3,
    /// Standard errors of ω (radians) and t (metres); none for a component the stable ground
    /// does not constrain (the fit leaves it at zero: the survey is not moved that way).
    pub(crate) rotation_sd: [Option<f64>; 3],
    pub(crate) translation_sd: [Option<f64>; 3],
    /// Degrees of freedom the stable ground constrains (of 6).
    pub(crate) constrained: usize,
    /// RMS over the stable points of the displacement along their normals the fit explains.
    pub(crate) effect_m: f64,
    /// Robust standard deviation of the residuals after the fit.
    pub(crate) residual_m: f64,
    /// What the residual would be from the surveys' noise alone: the median over the stable
    /// points of LoD95 / 1.96, the standard error of one M3C2 distance from its cylinders'
    /// spreads and counts.
    pub(crate) noise_m: f64,
    pub(crate) chi2: f64,
    pub(crate) stable_points: usize,
    /// The least, over the directions the fit constrains well ([`WELL_SEEN`]), share of what
    /// the core points tell of that direction (Σ (a·v)² over the pool) that comes from core points the fit leaves at
    /// rest: near 1 when a misregistration was removed, small when the fit holds still only a
    /// self-selected part of ground that moves.
    pub(crate) at_rest_share: f64,
    /// The share of its predicted change the held-out blocks of stable ground confirm
    /// ([`holdout`]); None where too few points could be held out.
    pub(crate) confirmed_share: Option<f64>,
    /// The largest displacement the transform gives a point of the stable ground's footprint (m).
    pub(crate) largest_shift_m: f64,
    /// Only the vertical was fitted (the stable ground does not see both tilts).
    pub(crate) vertical_only: bool,
    /// Rigid, significant, at rest and confirmed out of sample, but beyond the limits: the
    /// surveys are far off (a datum, a CRS), not misregistered by a fraction of a metre.
    pub(crate) gross: bool,
    pub(crate) applied: bool,
    /// The transform is known: enough stable ground, seeing the vertical and both tilts, that
    /// holds still as one rigid body, at rest, once it is removed (every rule of the module's
    /// header but the significance (3) and the effect (5)).
    /// A known transform that is not applied is known to be too small to matter: a chain of
    /// alignments may pass through it as the identity ([`super::chain`]); an unknown one it may not.
    pub(crate) determined: bool,
    /// Why it was, or was not, applied.
    pub(crate) reason: String,
}

impl Alignment {
    /// No fit (`reason` says why): the identity, not applied.
    pub(crate) fn none(reason: String) -> Alignment {
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
            confirmed_share: None,
            largest_shift_m: 0.0,
            vertical_only: false,
            gross: false,
            applied: false,
            determined: false,
            reason,
        }
    }

    /// The 4×4 matrix (row-major) mapping the later epoch's coordinates onto the earlier's: the
    /// inverse of the misregistration, with the exact rotation of ω (Rodrigues).
    pub(crate) fn matrix(&self) -> [[f64; 4]; 4] {
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
    #[cfg(test)]
    pub(crate) fn apply(&self, p: &Point3) -> Point3 {
        let m = self.matrix();
        let mut out = [0.0; 3];
        for (i, o) in out.iter_mut().enumerate() {
            *o = m[i][0] * p[0] + m[i][1] * p[1] + m[i][2] * p[2] + m[i][3];
        }
        out
    }

    /// The rotation's angle in degrees.
    pub(crate) fn rotation_deg(&self) -> f64 {
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

/// The vertical shift alone over `idx` (least squares of d = n_z t_z), as the six-parameter
/// vector (ω, t) with only t_z set.
fn solve_vertical(samples: &[Sample], idx: &[usize]) -> Vector6<f64> {
    let (mut nn, mut nd) = (0.0, 0.0);
    for &i in idx {
        let nz = samples[i].normal[2];
        nn += nz * nz;
        nd += nz * samples[i].distance;
    }
    let t = if nn > 0.0 { nd / nn } else { 0.0 };
    Vector6::new(0.0, 0.0, 0.0, 0.0, 0.0, t)
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
/// turn.) `sigma_d` is the noise of one distance on stable ground; `limits` bound a plausible
/// misregistration.
pub(crate) fn fit(
    samples: &[Sample],
    stable: &[usize],
    pool: &[usize],
    sigma_d: f64,
    limits: &Limits,
    ground: Ground,
) -> Alignment {
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
    // Vertical and both tilts: the unit vertical translation and the horizontal rotations.
    let sees = |dir: Vector6<f64>| -> bool {
        let dir = dir.normalize();
        let seen: f64 = kept
            .iter()
            .map(|&k| eig.eigenvectors.column(k).dot(&dir).powi(2))
            .sum();
        seen > 0.99
    };
    let vertical_seen = sees(Vector6::new(0.0, 0.0, 0.0, 0.0, 0.0, 1.0));
    let tilts = sees(Vector6::new(1.0, 0.0, 0.0, 0.0, 0.0, 0.0))
        && sees(Vector6::new(0.0, 1.0, 0.0, 0.0, 0.0, 0.0));
    // The vertical alone where the tilts are not seen: DoD practice's bias on stable ground.
    let vertical_only = vertical_seen && !tilts;
    let (p, kept) = if vertical_only {
        (solve_vertical(samples, &keep), vec![])
    } else {
        (p, kept)
    };
    let residual =
        |p: &Vector6<f64>, i: usize| samples[i].distance - row(&samples[i], &o, scale).dot(p);
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
    // Covariance of the kept directions: σ² Σ v vᵀ / λ (the vertical alone: σ² / Σ n_z²).
    let var = sigma * sigma;
    let mut cov = Matrix6::zeros();
    let mut chi2 = 0.0;
    for &k in &kept {
        let v = eig.eigenvectors.column(k);
        cov += v * v.transpose() * (var / eig.eigenvalues[k]);
        let along = v.dot(&p);
        chi2 += along * along * eig.eigenvalues[k] / var.max(f64::MIN_POSITIVE);
    }
    if vertical_only {
        let nn: f64 = keep.iter().map(|&i| samples[i].normal[2].powi(2)).sum();
        cov[(5, 5)] = var / nn.max(f64::MIN_POSITIVE);
        chi2 = p[5] * p[5] / cov[(5, 5)].max(f64::MIN_POSITIVE);
    }
    let effect = (keep
        .iter()
        .map(|&i| row(&samples[i], &o, scale).dot(&p).powi(2))
        .sum::<f64>()
        / keep.len().max(1) as f64)
        .sqrt();
    // A parameter with a part in an unconstrained direction has no standard error.
    let free = |k: usize| -> f64 {
        if vertical_only {
            return if k == 5 { 0.0 } else { 1.0 };
        }
        (0..6)
            .filter(|j| !kept.contains(j))
            .map(|j| eig.eigenvectors[(k, j)].powi(2))
            .sum()
    };
    let sd = |k: usize, unit: f64| (free(k) < 1e-3).then(|| cov[(k, k)].max(0.0).sqrt() / unit);
    let dof = if vertical_only { 1 } else { kept.len() };
    let at_rest = if vertical_only {
        // The share of the vertical's information from ground at rest.
        let (mut all, mut still) = (0.0, 0.0);
        for &i in pool {
            let w = samples[i].normal[2].powi(2);
            all += w;
            if residual(&p, i).abs() <= super::stable::KEEP_SIGMAS * sigma.max(noise) {
                still += w;
            }
        }
        still / all
    } else {
        at_rest_share(
            pool,
            &kept,
            &eig,
            |i| row(&samples[i], &o, scale),
            |i| residual(&p, i).abs() <= super::stable::KEEP_SIGMAS * sigma.max(noise),
        )
    };
    let confirmed = holdout::confirmed_share(samples, &keep, pool, &o, scale, vertical_only);
    let (w, t) = (
        Vector3::new(p[0], p[1], p[2]) / scale,
        Vector3::new(p[3], p[4], p[5]),
    );
    let (largest, turn, tilt) = size(&w, &t, &o, pool.iter().map(|&i| samples[i].xyz));
    let (applied, determined, gross, reason) = decide(&Figures {
        stable: keep.len(),
        vertical: vertical_seen,
        vertical_only,
        dof,
        chi2,
        sigma,
        noise,
        at_rest,
        effect,
        sigma_d,
        confirmed,
        largest,
        turn,
        tilt,
        limits: *limits,
        ground,
    });
    Alignment {
        rotation: [w[0], w[1], w[2]],
        translation: [t[0], t[1], t[2]],
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
        confirmed_share: confirmed.is_finite().then_some(confirmed),
        largest_shift_m: largest,
        vertical_only,
        gross,
        applied,
        determined,
        reason,
    }
}

/// The fit over `samples`: their stable ground, its noise, the rigid transform within `limits`.
/// The stable ground is first sought near zero distance ([`super::stable::select`]); where that
/// finds none, or none that holds still, the surveys may be far apart (every distance large):
/// the fit is tried again over every sample, its stable set re-selected from its own residuals,
/// and taken when it applies or is a gross misregistration. The noise of one distance, σ_d, is
/// the stable ground's robust spread ([`super::stable::spread`]).
pub(crate) fn find(samples: &[Sample], limits: &Limits, ground: Ground) -> Alignment {
    let finite: Vec<usize> = (0..samples.len())
        .filter(|&i| samples[i].distance.is_finite() && samples[i].normal[0].is_finite())
        .collect();
    let sel = super::stable::select(samples);
    let sigma_d = sel.as_ref().map_or_else(
        || {
            // No stable ground to measure the noise on: the distances' own LoDs say it.
            let mut l: Vec<f64> = finite.iter().map(|&i| samples[i].lod / 1.96).collect();
            median(&mut l)
        },
        |sel| super::stable::spread(samples, sel),
    );
    let near = match &sel {
        Some(sel) => fit(samples, &sel.keep, &sel.finite, sigma_d, limits, ground),
        None => Alignment::none(format!(
            "not applied: no stable ground among the {} core points sampled",
            samples.len()
        )),
    };
    if near.applied || near.determined || finite.len() < MIN_POINTS {
        return near;
    }
    let wide = fit(samples, &finite, &finite, sigma_d, limits, ground);
    if wide.applied || wide.gross {
        return Alignment {
            reason: format!(
                "{} (near zero distance: {}; over every core point sampled)",
                wide.reason, near.reason
            ),
            ..wide
        };
    }
    near
}

/// The fit `user` on the user's stable areas (over `inside`, their samples), its free
/// directions — those its ground does not see: a flat area sees no horizontal shift and no turn
/// about the vertical — taken from the rest of the surveys' stable ground (the fit over `rest`,
/// the automatic sample), so that a misregistration the areas cannot see is still removed.
/// Where the rest cannot fix them either, the fit is the areas' alone, and says so.
pub(crate) fn complete(
    user: &Alignment,
    inside: &[Sample],
    rest: &[Sample],
    limits: &Limits,
) -> Alignment {
    let other = find(rest, limits, Ground::Automatic);
    let free: Vec<usize> = (0..6)
        .filter(|&k| {
            if k < 3 {
                user.rotation_sd[k].is_none()
            } else {
                user.translation_sd[k - 3].is_none()
            }
        })
        .collect();
    let names = [
        "turn about x",
        "turn about y",
        "turn about z",
        "x",
        "y",
        "z",
    ];
    let said: Vec<&str> = free.iter().map(|&k| names[k]).collect();
    if !other.determined || other.gross {
        return Alignment {
            reason: format!(
                "{}; the directions the stable areas leave free ({}) could not be fitted on the \
                 rest of the surveys' stable ground ({}): a misregistration along them is not \
                 removed, and the intervals do not hold it",
                user.reason,
                said.join(", "),
                other.reason
            ),
            ..user.clone()
        };
    }
    // The areas' own directions as they fitted them (nothing, where their motion was within its
    // uncertainty), the free ones from the rest, every translation about the areas' origin.
    let keep_user = user.applied;
    let o = Vector3::from(user.origin);
    let w_rest = Vector3::from(other.rotation);
    let t_rest =
        Vector3::from(other.translation) + w_rest.cross(&(o - Vector3::from(other.origin)));
    let mut a = user.clone();
    for k in 0..3 {
        let (fr, ft) = (free.contains(&k), free.contains(&(k + 3)));
        a.rotation[k] = if fr {
            other.rotation[k]
        } else if keep_user {
            user.rotation[k]
        } else {
            0.0
        };
        a.translation[k] = if ft {
            t_rest[k]
        } else if keep_user {
            user.translation[k]
        } else {
            0.0
        };
        if fr {
            a.rotation_sd[k] = other.rotation_sd[k];
        }
        if ft {
            a.translation_sd[k] = other.translation_sd[k];
        }
    }
    a.constrained = (user.constrained + free.len()).min(6);
    let (w, t) = (Vector3::from(a.rotation), Vector3::from(a.translation));
    let (largest, turn, tilt) = size(&w, &t, &o, inside.iter().chain(rest).map(|s| s.xyz));
    a.largest_shift_m = largest;
    let plausible = limits.admit(largest, turn);
    a.applied = (user.applied || other.applied) && plausible && tilt <= limits.turn_deg;
    a.determined = user.determined && other.determined && plausible;
    a.reason = format!(
        "{}: {} of 6 directions from the stable areas ({}), {} ({}) from the rest of the \
         surveys' stable ground ({} core points: {})",
        if a.applied {
            "applied"
        } else if plausible {
            "not applied"
        } else {
            "not applied, beyond a registration error's size"
        },
        6 - free.len(),
        user.reason,
        free.len(),
        said.join(", "),
        other.stable_points,
        other.reason
    );
    a
}

/// The size of the motion ω, t about `o` over the points `at`: the largest displacement of any
/// of them, |t + ω × (c − o)| (at least |t|), its turn and its tilt (the turn about horizontal
/// axes), in degrees.
fn size(
    w: &Vector3<f64>,
    t: &Vector3<f64>,
    o: &Vector3<f64>,
    at: impl Iterator<Item = Point3>,
) -> (f64, f64, f64) {
    let largest = at
        .map(|c| (t + w.cross(&(Vector3::from(c) - o))).norm())
        .fold(t.norm(), f64::max);
    (
        largest,
        w.norm().to_degrees(),
        w[0].hypot(w[1]).to_degrees(),
    )
}

/// What [`fit`] measured, for [`decide`].
struct Figures {
    stable: usize,
    vertical: bool,
    vertical_only: bool,
    dof: usize,
    chi2: f64,
    sigma: f64,
    noise: f64,
    at_rest: f64,
    effect: f64,
    sigma_d: f64,
    confirmed: f64,
    largest: f64,
    turn: f64,
    tilt: f64,
    limits: Limits,
    ground: Ground,
}

/// Whether a fit is applied, whether it is determined ([`Alignment::determined`]), whether it is
/// a gross misregistration ([`Alignment::gross`]), and why: the rules of the module's header, in
/// order.
fn decide(f: &Figures) -> (bool, bool, bool, String) {
    let &Figures {
        stable,
        vertical,
        vertical_only,
        dof,
        chi2,
        sigma,
        noise,
        at_rest,
        effect,
        sigma_d,
        confirmed,
        largest,
        turn,
        tilt,
        limits,
        ground,
    } = f;
    let rigid = !(sigma.is_nan() || noise.is_nan() || sigma > RIGID * noise);
    let at_rest_ok = !(at_rest.is_nan() || at_rest < AT_REST);
    let enough = stable >= min_points(dof);
    let determined = enough && vertical && rigid && at_rest_ok;
    let what = if vertical_only {
        "the vertical alone (the stable ground does not see both tilts)".to_string()
    } else {
        format!("{dof} of 6 directions")
    };
    let not = if !enough {
        format!(
            "not applied: {stable} stable core points, fewer than {} for {what}",
            min_points(dof)
        )
    } else if !vertical {
        format!("not applied: the stable ground constrains {dof} of 6 directions, not the vertical")
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
    } else if ground == Ground::Automatic
        && (confirmed.is_nan() || !(HOLDS_OUT..=2.0 - HOLDS_OUT).contains(&confirmed))
    {
        let share = if confirmed.is_nan() {
            "too little of it could be held out to check".to_string()
        } else {
            format!(
                "fitted on all but one block of the stable ground, it explains {:.0} % of what \
                 it predicts on the held-out block ({:.0} to {:.0} %: one motion explains all it \
                 predicts there, no less and no more)",
                100.0 * confirmed.clamp(-9.99, 9.99),
                100.0 * HOLDS_OUT,
                100.0 * (2.0 - HOLDS_OUT)
            )
        };
        // Unconfirmed, it is not a misregistration known to be there; below the noise of one
        // distance it is known to be too small to matter (a chain may pass it as the identity).
        return (
            false,
            determined && effect < sigma_d,
            false,
            format!(
                "not applied: it does not hold out of sample: {share}; what it fits is not one \
                 motion of the whole survey (change, or ground moving from place to place)"
            ),
        );
    } else if tilt > limits.turn_deg {
        // A survey is levelled (a scanner's compensator, GNSS/INS, control points): a tilt of
        // degrees is no misregistration, small or gross, but change or a distorted datum fitted.
        return (
            false,
            false,
            false,
            format!(
                "not applied: it tilts the survey by {tilt:.3}° (turn {turn:.3}°, shift up to \
                 {largest:.3} m), more than any levelled survey is off ({}°): what it fits is \
                 change or a distorted surface, not a misregistration",
                limits.turn_deg
            ),
        );
    } else if !limits.admit(largest, turn) {
        return (
            false,
            false,
            true,
            format!(
                "not applied: it moves the survey by up to {largest:.3} m and turns it \
                 {turn:.3}°, more than a registration error leaves ({} m, {}°): the surveys are \
                 far apart (another datum or CRS, a georeferencing error)",
                limits.shift_m, limits.turn_deg
            ),
        );
    } else {
        return (
            true,
            true,
            false,
            format!(
                "applied: {what} constrained by {stable} stable points; it moves them by \
                 {effect:.4} (RMS along the normals), χ² {chi2:.0}, and explains {} of what it \
                 predicts on held-out ground{}",
                if confirmed.is_nan() {
                    "an unknown share".to_string()
                } else {
                    format!("{:.0} %", 100.0 * confirmed)
                },
                if ground == Ground::User {
                    " (the user's stable ground: not required)"
                } else {
                    ""
                }
            ),
        );
    };
    (false, determined, false, not)
}

#[cfg(test)]
mod tests;
