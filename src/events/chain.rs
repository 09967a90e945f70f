//! A campaign's surveys brought into the first survey's frame, each directly or through its
//! predecessors (SPEC.md §1 "Registration": "chained through its predecessors where they share
//! more stable ground").
//!
//! Survey k has two fits ([`super::align::fit`]): onto the first survey, and onto survey k − 1.
//! Its route is either the direct fit, or the fit onto k − 1 followed by k − 1's own route. A
//! route is only as good as its weakest link, so each route is weighed by the stable ground of
//! that link — the core points it was fitted on — and the route that shares more is taken (the
//! widest path through the chain; a tie keeps the direct fit, which has fewer links to add
//! errors). Ground that is stable between neighbours but not since the first survey (a beach
//! rebuilt a season at a time, a slope that moved once) is what makes a chain win.
//!
//! A link may be passed only when its transform is known ([`Alignment::determined`]): applied,
//! or measured and too small to matter (then the identity). A link whose stable ground cannot
//! fix it (too few points, moving ground) breaks the chain there. A route with every link
//! unapplied is the identity: the survey is read as it is, byte for byte as with `--align off`.
//!
//! The links are fitted on different pairs of surveys, with independent noise: the standard
//! errors of a chained route are the links' added in quadrature (their covariances, and the
//! change of the rotation's origin from link to link, neglected: second order for turns of a
//! fraction of a degree).

use nalgebra::{Matrix3, Rotation3, Vector3};
use serde::{Deserialize, Serialize};

use super::align::Alignment;

/// The two fits of survey k ≥ 1: onto the first survey, and onto its predecessor (none for
/// survey 1, whose predecessor is the first).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct Fits {
    pub(crate) onto_first: Alignment,
    pub(crate) onto_previous: Option<Alignment>,
}

/// How a survey reaches the first survey's frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct Route {
    /// The surveys it passes through, from the survey itself to the first (0).
    pub(crate) surveys: Vec<usize>,
    /// Stable core points of its weakest link (0 when no route is known).
    pub(crate) shared: usize,
    /// The transform of the whole route: the direct fit itself when it has one link.
    pub(crate) alignment: Alignment,
}

/// The route of every survey, given each survey's fits (`fits[k]`; none for the first survey
/// and for a survey the plan does not align).
pub(crate) fn routes(fits: &[Option<Fits>]) -> Vec<Option<Route>> {
    let mut out: Vec<Option<Route>> = Vec::with_capacity(fits.len());
    for (k, f) in fits.iter().enumerate() {
        let Some(f) = f else {
            out.push(None);
            continue;
        };
        let direct = Route {
            surveys: vec![k, 0],
            shared: weight(&f.onto_first),
            alignment: f.onto_first.clone(),
        };
        let chained = match (&f.onto_previous, k.checked_sub(1).and_then(|p| out.get(p))) {
            (Some(link), Some(Some(prev))) if k >= 2 && prev.shared > 0 && weight(link) > 0 => {
                Some(chain(k, link, prev))
            }
            _ => None,
        };
        out.push(Some(match chained {
            Some(c) if c.shared > direct.shared => c,
            _ => direct,
        }));
    }
    out
}

/// What a fit weighs as a link: its stable core points when its transform is known, else 0.
fn weight(a: &Alignment) -> usize {
    if a.determined {
        a.stable_points
    } else {
        0
    }
}

/// Survey k's route through its predecessor: `link` (k onto k − 1) followed by `prev`.
fn chain(k: usize, link: &Alignment, prev: &Route) -> Route {
    let p = &prev.alignment;
    let applied = link.applied || p.applied;
    let mut surveys = vec![k];
    surveys.extend(&prev.surveys);
    let shared = link.stable_points.min(prev.shared);
    // Only the applied links move the survey; the others are the identity.
    let m = compose(&matrix_if(p), &matrix_if(link));
    let (rotation, translation) = if applied {
        motion(&m, &link.origin)
    } else {
        ([0.0; 3], [0.0; 3])
    };
    let quad = |a: Option<f64>, b: Option<f64>| Some(a?.hypot(b?));
    let path = surveys
        .iter()
        .map(|s| s.to_string())
        .collect::<Vec<_>>()
        .join(" → ");
    let reason = if applied {
        format!(
            "applied through {path}: the route that shares the most stable ground with the \
             first survey ({shared} core points at its weakest link); onto {}: {}",
            k - 1,
            link.reason
        )
    } else {
        format!(
            "not applied: every link of {path} (the route that shares the most stable ground, \
             {shared} core points at its weakest link) is too small to matter"
        )
    };
    Route {
        surveys,
        shared,
        alignment: Alignment {
            rotation,
            translation,
            origin: link.origin,
            rotation_sd: std::array::from_fn(|i| quad(link.rotation_sd[i], p.rotation_sd[i])),
            translation_sd: std::array::from_fn(|i| {
                quad(link.translation_sd[i], p.translation_sd[i])
            }),
            constrained: link.constrained.min(p.constrained),
            effect_m: link.effect_m.hypot(p.effect_m),
            residual_m: link.residual_m.max(p.residual_m),
            noise_m: link.noise_m.max(p.noise_m),
            chi2: link.chi2 + p.chi2,
            stable_points: shared,
            at_rest_share: link.at_rest_share.min(p.at_rest_share),
            confirmed_share: match (link.confirmed_share, p.confirmed_share) {
                (Some(a), Some(b)) => Some(a.min(b)),
                (a, b) => a.or(b),
            },
            largest_shift_m: link.largest_shift_m + p.largest_shift_m,
            vertical_only: link.vertical_only && p.vertical_only,
            gross: false,
            applied,
            determined: true,
            reason,
        },
    }
}

type Matrix4 = [[f64; 4]; 4];

/// `a`'s matrix when it is applied, else the identity.
fn matrix_if(a: &Alignment) -> Matrix4 {
    if a.applied {
        a.matrix()
    } else {
        std::array::from_fn(|i| std::array::from_fn(|j| if i == j { 1.0 } else { 0.0 }))
    }
}

/// The matrix product a · b (b applied first).
fn compose(a: &Matrix4, b: &Matrix4) -> Matrix4 {
    std::array::from_fn(|i| std::array::from_fn(|j| (0..4).map(|k| a[i][k] * b[k][j]).sum()))
}

/// The misregistration (rotation vector about `o`, translation) whose [`Alignment::matrix`] is
/// `m`: m = [Rᵀ | o − Rᵀ(o + t)], so R = Aᵀ and t = R (o − b) − o.
fn motion(m: &Matrix4, o: &[f64; 3]) -> ([f64; 3], [f64; 3]) {
    let a = Matrix3::from_fn(|i, j| m[i][j]);
    let r = a.transpose();
    let w = Rotation3::from_matrix_unchecked(r).scaled_axis();
    let o = Vector3::from(*o);
    let b = Vector3::new(m[0][3], m[1][3], m[2][3]);
    let t = r * (o - b) - o;
    ([w[0], w[1], w[2]], [t[0], t[1], t[2]])
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A fit of `stable` points moving the later survey by (ω, t) about `o`; applied and
    /// determined as asked.
    fn fit(w: [f64; 3], t: [f64; 3], o: [f64; 3], stable: usize, applied: bool) -> Alignment {
        let mut a = Alignment::none(String::new());
        a.rotation = w;
        a.translation = t;
        a.origin = o;
        a.rotation_sd = [Some(1e-5); 3];
        a.translation_sd = [Some(0.002); 3];
        a.constrained = 6;
        a.stable_points = stable;
        a.applied = applied;
        a.determined = true;
        a
    }

    fn map(m: &Matrix4, p: [f64; 3]) -> [f64; 3] {
        std::array::from_fn(|i| m[i][0] * p[0] + m[i][1] * p[1] + m[i][2] * p[2] + m[i][3])
    }

    /// A survey moved by one misregistration, then another: chained through its predecessor,
    /// its points land where the two inverse transforms put them, one after the other; the
    /// route's (ω, t) reproduce that matrix.
    #[test]
    fn a_chain_composes_its_links() {
        let d = 0.1f64.to_radians();
        let first = fit(
            [0.0, 0.0, 2.0 * d],
            [0.05, -0.03, 0.02],
            [10.0, 5.0, 100.0],
            900,
            true,
        );
        let link = fit(
            [d, -d, 0.5 * d],
            [-0.02, 0.04, 0.07],
            [30.0, -8.0, 110.0],
            1000,
            true,
        );
        let mut weak = first.clone();
        weak.stable_points = 300;
        let fits = [
            None,
            Some(Fits {
                onto_first: first.clone(),
                onto_previous: None,
            }),
            Some(Fits {
                onto_first: weak,
                onto_previous: Some(link.clone()),
            }),
        ];
        let r = routes(&fits);
        let two = r[2].as_ref().unwrap();
        assert_eq!(two.surveys, vec![2, 1, 0]);
        assert_eq!(two.shared, 900);
        assert!(two.alignment.applied && two.alignment.reason.starts_with("applied through"));
        let m = two.alignment.matrix();
        for p in [[0.0, 0.0, 0.0], [40.0, -20.0, 130.0], [12.5, 3.0, 95.0]] {
            let expect = first.apply(&link.apply(&p));
            let got = map(&m, p);
            for i in 0..3 {
                assert!((got[i] - expect[i]).abs() < 1e-9, "{got:?} vs {expect:?}");
            }
        }
        // Standard errors added in quadrature.
        let sd = two.alignment.translation_sd[0].unwrap();
        assert!((sd - 0.002 * 2f64.sqrt()).abs() < 1e-12);
    }

    /// The route sharing more stable ground at its weakest link wins; a tie keeps the direct
    /// fit; a link whose transform is unknown is never passed, nor a predecessor with no route.
    #[test]
    fn the_widest_route_is_taken() {
        let o = [0.0; 3];
        let a = |stable| fit([0.0; 3], [0.01, 0.0, 0.0], o, stable, true);
        let fits = |first1: Alignment, first2: Alignment, prev2: Alignment| {
            routes(&[
                None,
                Some(Fits {
                    onto_first: first1,
                    onto_previous: None,
                }),
                Some(Fits {
                    onto_first: first2,
                    onto_previous: Some(prev2),
                }),
            ])
        };
        let via = |r: &[Option<Route>]| r[2].as_ref().unwrap().surveys.clone();
        // 1 → 0 shares 800 and 2 → 1 shares 5000: the chain's weakest link (800) beats the
        // direct fit's 500.
        assert_eq!(via(&fits(a(800), a(500), a(5000))), vec![2, 1, 0]);
        // The chain's weakest link (400) is less than the direct fit's (500).
        assert_eq!(via(&fits(a(400), a(500), a(5000))), vec![2, 0]);
        // A tie keeps the direct fit.
        assert_eq!(via(&fits(a(500), a(500), a(5000))), vec![2, 0]);
        // An unknown link (its ground moved) is not passed, however much it shares.
        let mut moving = a(5000);
        moving.determined = false;
        moving.applied = false;
        assert_eq!(via(&fits(a(800), a(500), moving)), vec![2, 0]);
        // Nor a predecessor whose own route is unknown.
        let mut lost = a(800);
        lost.determined = false;
        lost.applied = false;
        assert_eq!(via(&fits(lost, a(500), a(5000))), vec![2, 0]);
        // A direct fit that is unknown loses to any known chain.
        let mut direct = a(9000);
        direct.determined = false;
        direct.applied = false;
        assert_eq!(via(&fits(a(300), direct, a(300))), vec![2, 1, 0]);
    }

    /// Links measured and too small to matter are the identity: a chain of them is not applied
    /// and moves nothing.
    #[test]
    fn a_chain_of_small_links_is_the_identity() {
        let small = |stable| fit([1e-7; 3], [1e-4, 0.0, 0.0], [5.0; 3], stable, false);
        let r = routes(&[
            None,
            Some(Fits {
                onto_first: small(800),
                onto_previous: None,
            }),
            Some(Fits {
                onto_first: small(500),
                onto_previous: Some(small(900)),
            }),
        ]);
        let two = r[2].as_ref().unwrap();
        assert_eq!(two.surveys, vec![2, 1, 0]);
        assert!(!two.alignment.applied);
        assert_eq!(two.alignment.rotation, [0.0; 3]);
        assert_eq!(two.alignment.translation, [0.0; 3]);
    }
}
