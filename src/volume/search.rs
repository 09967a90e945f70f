//! Where an event's volume looks for its two surfaces (SPEC.md §1 "Volume"): the event's box
//! grown by the volume margin and three point spacings across, and along its normal as deep as
//! the M3C2 cylinder's half-length — or, where the event's distances reach further (a change
//! deeper than the window, measured by M3C2's walk, `m3c2::reach`), its deepest distance plus
//! the margin. The events unit files each event by the tiles its boxes reach and the volumes
//! unit gathers the points inside them: both ask here, so they agree.

use super::Frame;
use crate::events::Obb;

/// The reach of an event's search boxes, from the run's parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Search {
    /// The volume margin of SPEC.md §1: cyl_radius + 2 × point spacing.
    pub(crate) margin: f64,
    /// The point spacing.
    pub(crate) spacing: f64,
    /// The M3C2 cylinder's half-length.
    pub(crate) cyl_halflen: f64,
}

impl Search {
    pub(crate) fn new(cyl_radius: f64, point_spacing: f64, cyl_halflen: f64) -> Search {
        Search {
            margin: cyl_radius + 2.0 * point_spacing,
            spacing: point_spacing,
            cyl_halflen,
        }
    }

    /// How far from the before surface, along the box's third axis, the volume of an event
    /// whose largest |distance| is `max_abs_distance` looks for the two surfaces.
    pub(crate) fn depth(&self, max_abs_distance: f64) -> f64 {
        self.cyl_halflen.max(max_abs_distance + self.margin)
    }

    /// The box (in the event's frame) whose points the volume needs, reaching `depth` beyond
    /// `obb`'s own extent along its third axis: its half extents and its XY bounds.
    pub(crate) fn search_box(&self, obb: &Obb, depth: f64) -> ([f64; 3], [f64; 4]) {
        // Summed in this order: the boxes' bits are part of what the units agree on.
        let (m, s) = (self.margin, self.spacing);
        let h = [
            obb.half_extents[0] + m + 3.0 * s,
            obb.half_extents[1] + m + 3.0 * s,
            obb.half_extents[2] + depth,
        ];
        let xy = Frame::of_obb(obb).bounds_xy(h.map(|x| -x), h);
        (h, xy)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_box_reaches_the_margin_across_and_the_deeper_of_window_and_distance_along() {
        let s = Search::new(0.5, 0.1, 2.0);
        assert!((s.margin - 0.7).abs() < 1e-12);
        assert_eq!(s.depth(0.3), 2.0);
        assert!((s.depth(5.0) - 5.7).abs() < 1e-12);
        let obb = Obb {
            center: [10.0, 20.0, 5.0],
            axes: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            half_extents: [1.0, 2.0, 0.5],
        };
        let (h, xy) = s.search_box(&obb, 3.0);
        assert!((h[0] - 2.0).abs() < 1e-12 && (h[1] - 3.0).abs() < 1e-12);
        assert!((h[2] - 3.5).abs() < 1e-12);
        for (got, want) in xy.iter().zip([8.0, 17.0, 12.0, 23.0]) {
            assert!((got - want).abs() < 1e-9, "{xy:?}");
        }
    }
}
