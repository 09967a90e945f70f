//! The event frame (SPEC.md §1 "Volume"): coordinates (u, v, w) along the rows of the
//! event's OBB axes, origin at the box centre. u, v span the footprint; w is the outward
//! surface normal, the direction of extrusion (not z, so cliffs and overhanging faces are
//! measured across the face, not through it).

use crate::events::Obb;

/// An orthonormal right-handed frame: global ↔ local (u, v, w).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Frame {
    pub(crate) origin: [f64; 3],
    /// Rows: the unit u, v, w axes in global coordinates.
    pub(crate) axes: [[f64; 3]; 3],
}

impl Frame {
    /// The frame of an OBB (origin at its centre).
    pub fn of_obb(obb: &Obb) -> Self {
        Frame {
            origin: obb.center,
            axes: obb.axes,
        }
    }
    /// Global → local.
    #[allow(clippy::wrong_self_convention)] // &self: no copy per point mapped
    pub(crate) fn to_local(&self, p: &[f64; 3]) -> [f64; 3] {
        let d = [
            p[0] - self.origin[0],
            p[1] - self.origin[1],
            p[2] - self.origin[2],
        ];
        self.axes.map(|a| a[0] * d[0] + a[1] * d[1] + a[2] * d[2])
    }
    /// The xy bounds [x0, y0, x1, y1] of the box [lo, hi] given in this frame (its 8 corners).
    pub(crate) fn bounds_xy(&self, lo: [f64; 3], hi: [f64; 3]) -> [f64; 4] {
        let mut b = [
            f64::INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NEG_INFINITY,
        ];
        for c in 0..8 {
            let l: [f64; 3] = std::array::from_fn(|k| if c >> k & 1 == 0 { lo[k] } else { hi[k] });
            let g = self.to_global(&l);
            b = [
                b[0].min(g[0]),
                b[1].min(g[1]),
                b[2].max(g[0]),
                b[3].max(g[1]),
            ];
        }
        b
    }

    /// Local → global.
    #[allow(clippy::wrong_self_convention)] // &self: no copy per point mapped
    pub(crate) fn to_global(&self, l: &[f64; 3]) -> [f64; 3] {
        let a = &self.axes;
        std::array::from_fn(|k| self.origin[k] + l[0] * a[0][k] + l[1] * a[1][k] + l[2] * a[2][k])
    }
}

/// The rectangle [u0, u1] × [v0, v1] in the frame over which both epochs are compared.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Footprint {
    pub(crate) u0: f64,
    pub(crate) u1: f64,
    pub(crate) v0: f64,
    pub(crate) v1: f64,
}

impl Footprint {
    /// The OBB's first two half extents grown by `margin` on every side.
    pub fn of_obb(obb: &Obb, margin: f64) -> Self {
        let (hu, hv) = (obb.half_extents[0] + margin, obb.half_extents[1] + margin);
        Footprint {
            u0: -hu,
            u1: hu,
            v0: -hv,
            v1: hv,
        }
    }
    /// The same rectangle grown by `d` on every side.
    pub(crate) fn grown(&self, d: f64) -> Self {
        Footprint {
            u0: self.u0 - d,
            u1: self.u1 + d,
            v0: self.v0 - d,
            v1: self.v1 + d,
        }
    }
    /// Area.
    pub(crate) fn area(&self) -> f64 {
        (self.u1 - self.u0) * (self.v1 - self.v0)
    }
    /// Is (u, v) inside (closed)?
    pub(crate) fn contains(&self, u: f64, v: f64) -> bool {
        u >= self.u0 && u <= self.u1 && v >= self.v0 && v <= self.v1
    }
}
