//! Orientation of core-point normals.
//!
//! The sign of every M3C2 distance follows the normal, so orientation must be consistent over
//! the surface. `up` flips normals to n·z ≥ 0, which is ambiguous on vertical faces (n·z ≈ 0:
//! noise flips signs point to point and smoothing then cancels a real rockfall); a fixed vector
//! or a point to face (`toward:`, the scanner's position) decide every sign the user's way.
//!
//! `auto` takes each sign from the survey's orientation field ([`super::field`]): the surface
//! sampled coarsely and oriented once as a whole, consistently along it and with one sign per
//! connected part chosen from gravity; a core point's normal agrees with the field near it, and
//! says whether the data decided its sign.

use std::str::FromStr;

use super::field::Field;
use crate::geom::{dot, Point3};

/// How normals are oriented (`--orientation`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Orientation {
    /// From the survey's orientation field (`super::field`): out of the material, decided
    /// over the whole surface.
    Auto,
    /// n·z ≥ 0.
    Up,
    /// n·v ≥ 0 for a fixed vector v.
    Vector(Point3),
    /// Toward a point (e.g. the scanner position), global coordinates.
    Toward(Point3),
}

impl std::fmt::Display for Orientation {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Orientation::Auto => write!(f, "auto"),
            Orientation::Up => write!(f, "up"),
            Orientation::Vector(v) => write!(f, "{},{},{}", v[0], v[1], v[2]),
            Orientation::Toward(p) => write!(f, "toward:{},{},{}", p[0], p[1], p[2]),
        }
    }
}

fn parse_triplet(s: &str) -> Option<Point3> {
    let v: Vec<f64> = s
        .split(',')
        .map(|t| t.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .ok()?;
    (v.len() == 3 && v.iter().all(|x| x.is_finite())).then(|| [v[0], v[1], v[2]])
}

impl FromStr for Orientation {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let bad = || format!("--orientation: expected auto, up, X,Y,Z or toward:X,Y,Z, got '{s}'");
        match s.trim() {
            "auto" => Ok(Orientation::Auto),
            "up" => Ok(Orientation::Up),
            t if t.starts_with("toward:") => parse_triplet(&t[7..])
                .map(Orientation::Toward)
                .ok_or_else(bad),
            t => {
                let v = parse_triplet(t).ok_or_else(bad)?;
                if v.iter().all(|x| *x == 0.0) {
                    return Err(format!("--orientation: the vector {t} has zero length"));
                }
                Ok(Orientation::Vector(v))
            }
        }
    }
}

/// A normal is steep (its "up" sign unreliable) when |n·z| is below this: about 60° from vertical.
pub(crate) const STEEP_NZ: f64 = 0.5;

fn flip(n: &mut Point3) {
    n[0] = -n[0];
    n[1] = -n[1];
    n[2] = -n[2];
}

/// Orient `normals` (unit, or NaN where undefined) at `cores` (a local frame whose origin is
/// `origin`, in global coordinates) in place; whether each sign is known. `auto` follows
/// `field` (the orientation field near the cores, in their frame); without one it turns
/// normals up and knows the signs of those that are not steep.
pub(crate) fn orient(
    cores: &[Point3],
    normals: &mut [Point3],
    origin: Point3,
    how: Orientation,
    field: Option<&Field>,
) -> Vec<bool> {
    match how {
        Orientation::Up => orient_along(normals, &[0.0, 0.0, 1.0]),
        Orientation::Vector(v) => orient_along(normals, &v),
        Orientation::Toward(target) => {
            let t = [
                target[0] - origin[0],
                target[1] - origin[1],
                target[2] - origin[2],
            ];
            for (p, n) in cores.iter().zip(normals.iter_mut()) {
                let to = [t[0] - p[0], t[1] - p[1], t[2] - p[2]];
                if dot(n, &to) < 0.0 {
                    flip(n);
                }
            }
        }
        Orientation::Auto => {
            let Some(field) = field else {
                orient_along(normals, &[0.0, 0.0, 1.0]);
                return normals
                    .iter()
                    .map(|n| !n[2].is_finite() || n[2].abs() >= STEEP_NZ)
                    .collect();
            };
            return cores
                .iter()
                .zip(normals.iter_mut())
                .map(|(p, n)| !n[0].is_finite() || field.orient(p, n))
                .collect();
        }
    }
    vec![true; normals.len()]
}

fn orient_along(normals: &mut [Point3], v: &Point3) {
    for n in normals.iter_mut() {
        if dot(n, v) < 0.0 {
            flip(n);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_all_forms() {
        assert_eq!("auto".parse::<Orientation>().unwrap(), Orientation::Auto);
        assert_eq!("up".parse::<Orientation>().unwrap(), Orientation::Up);
        assert_eq!(
            "0,1,0".parse::<Orientation>().unwrap(),
            Orientation::Vector([0.0, 1.0, 0.0])
        );
        assert_eq!(
            "toward:1,2,3".parse::<Orientation>().unwrap(),
            Orientation::Toward([1.0, 2.0, 3.0])
        );
        assert!("sideways".parse::<Orientation>().is_err());
        assert!("0,0,0".parse::<Orientation>().is_err());
    }
}
