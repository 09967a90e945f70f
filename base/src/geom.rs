//! The geometry every layer shares: a point in global coordinates and axis-aligned bounds. It
//! sits below the algorithms and the formats, so neither imports the other for a point type.

/// One point in global coordinates.
pub type Point3 = [f64; 3];

/// Axis-aligned bounds of a cloud.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Bounds {
    pub min: Point3,
    pub max: Point3,
}

impl Bounds {
    /// The bounds of all of `bounds`.
    pub fn union(bounds: &[Bounds]) -> Bounds {
        let mut u = Bounds::empty();
        for b in bounds {
            u.grow(&b.min);
            u.grow(&b.max);
        }
        u
    }

    /// Empty bounds (min = +inf, max = -inf), ready to [`Bounds::grow`].
    pub fn empty() -> Self {
        Bounds {
            min: [f64::INFINITY; 3],
            max: [f64::NEG_INFINITY; 3],
        }
    }
    /// The bounds of `points`.
    pub fn of<'a>(points: impl IntoIterator<Item = &'a Point3>) -> Self {
        let mut b = Bounds::empty();
        for p in points {
            b.grow(p);
        }
        b
    }
    /// Extend to contain `p`.
    pub fn grow(&mut self, p: &Point3) {
        for ((lo, hi), &v) in self.min.iter_mut().zip(&mut self.max).zip(p) {
            *lo = lo.min(v);
            *hi = hi.max(v);
        }
    }
    /// True when no point was added.
    pub fn is_empty(&self) -> bool {
        self.min[0] > self.max[0]
    }
    /// Do the XY footprints of the two bounds intersect?
    pub fn overlaps_xy(&self, other: &Bounds) -> bool {
        self.min[0] <= other.max[0]
            && other.min[0] <= self.max[0]
            && self.min[1] <= other.max[1]
            && other.min[1] <= self.max[1]
    }
}

/// The dot product of two vectors.
pub fn dot(a: &Point3, b: &Point3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// A coordinate or length for a message: three decimals, or scientific notation where those
/// would run to hundreds of digits (coordinates of 1e295 in a damaged file).
pub fn show(x: f64) -> String {
    if x.is_finite() && x.abs() < 1e12 {
        format!("{x:.3}")
    } else {
        format!("{x:.3e}")
    }
}
