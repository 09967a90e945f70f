//! Can a plan yield any distance at all? Decided from the surveys' and core points' bounds (the
//! headers': every point lies within them, `io` refuses one that does not) and the resolved
//! parameters, before anything is computed: a core point gets a normal only from before-epoch
//! points within the normal radius, and a distance only from points of both epochs inside its
//! cylinder, which lies within √(r² + h²) of it. Epochs (or core points) farther apart than that
//! would give a result of empty columns with exit 0; they are refused (exit 2) with the reason.

use crate::error::{Error, Result};
use crate::io::Bounds;
use crate::plan::Plan;

/// Per axis, how far apart `a` and `b` are (0 where their ranges meet).
pub(crate) fn gap(a: &Bounds, b: &Bounds) -> [f64; 3] {
    std::array::from_fn(|i| (a.min[i] - b.max[i]).max(b.min[i] - a.max[i]).max(0.0))
}

fn norm(v: [f64; 3]) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

/// `z 99.997..101.203` for the axes where `gap` is not zero (all three when none is).
fn ranges(b: &Bounds, gap: [f64; 3]) -> String {
    let any = gap.iter().any(|&g| g > 0.0);
    (0..3)
        .filter(|&i| !any || gap[i] > 0.0)
        .map(|i| {
            let show = crate::geom::show;
            format!(
                "{} {}..{}",
                ["x", "y", "z"][i],
                show(b.min[i]),
                show(b.max[i])
            )
        })
        .collect::<Vec<_>>()
        .join(", ")
}

/// Is `gap` beyond `reach` (with a margin for rounding)?
fn beyond(gap: f64, reach: f64) -> bool {
    gap > reach * (1.0 + 1e-9) + 1e-9
}

/// Refuse the plan when a pair's epochs, or the core points (`cores`: what they are, e.g. "the
/// core points FILE", and their bounds), lie too far apart for any core point to get a distance.
pub(crate) fn check(plan: &Plan, cores: Option<(&str, &Bounds)>) -> Result<()> {
    let p = &plan.params;
    let (nr, r, h) = (
        p.normal_radius.value,
        p.cyl_radius.value,
        p.cyl_halflen.value,
    );
    let reach = r.hypot(h);
    let cylinder = format!(
        "M3C2's cylinder reaches {reach:.3} from a core point (radius {r:.3}, half-length {h:.3})"
    );
    for (k, pair) in plan.pairs.iter().enumerate() {
        let (b, a) = (&plan.surveys[pair.before], &plan.surveys[pair.after]);
        let what = plan.pair_name(k);
        let g = gap(&b.bounds, &a.bounds);
        if beyond(norm(g), reach) {
            return Err(Error::Epochs(format!(
                "{what}: the epochs do not overlap: before {}; after {} ({} apart, and {cylinder})",
                ranges(&b.bounds, g),
                ranges(&a.bounds, g),
                crate::geom::show(norm(g))
            )));
        }
        let Some((name, c)) = cores else { continue };
        let (gb, ga) = (gap(c, &b.bounds), gap(c, &a.bounds));
        if beyond(norm(gb), nr.min(reach)) && beyond(norm(ga), reach) {
            return Err(Error::Epochs(format!(
                "{what}: {name} ({}) lie outside both epochs' bounds (before: {}; after: {})",
                ranges(c, [0.0; 3]),
                ranges(&b.bounds, [0.0; 3]),
                ranges(&a.bounds, [0.0; 3]),
            )));
        }
        let how = if nr < reach {
            format!("the normal radius {nr:.3} (normals come from the before epoch)")
        } else {
            cylinder.clone()
        };
        let (epoch, e, g, how) = if beyond(norm(gb), nr.min(reach)) {
            ("before", b, gb, how)
        } else if beyond(norm(ga), reach) {
            ("after", a, ga, cylinder.clone())
        } else {
            continue;
        };
        return Err(Error::Epochs(format!(
            "{what}: {name} ({}) lie outside the {epoch} epoch's bounds ({}): {} away, beyond {how}",
            ranges(c, g),
            ranges(&e.bounds, g),
            crate::geom::show(norm(g)),
        )));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn b(min: [f64; 3], max: [f64; 3]) -> Bounds {
        Bounds { min, max }
    }

    #[test]
    fn gaps_per_axis() {
        let a = b([0.0, 0.0, 0.0], [1.0, 1.0, 1.0]);
        assert_eq!(
            gap(&a, &b([0.5, 3.0, -5.0], [2.0, 4.0, -1.0])),
            [0.0, 2.0, 1.0]
        );
        assert_eq!(gap(&a, &a), [0.0; 3]);
        assert_eq!(ranges(&a, [0.0, 0.0, 2.0]), "z 0.000..1.000");
    }
}
