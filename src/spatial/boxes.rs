//! A coarse xy grid over axis-aligned boxes: which boxes may contain a point (the events' search
//! boxes when points are gathered, their claims when a location's owner is looked up).

use rustc_hash::FxHashMap as HashMap;

/// Boxes [x0, y0, x1, y1] bucketed on a grid of cells the size of the median box: a box covers a
/// few cells, a cell holds a few boxes.
pub(crate) struct BoxIndex {
    origin: [f64; 2],
    cell: f64,
    boxes: Vec<[f64; 4]>,
    cells: HashMap<(i64, i64), Vec<usize>>,
}

impl BoxIndex {
    pub(crate) fn new(boxes: &[[f64; 4]]) -> Self {
        let mut ext: Vec<f64> = boxes
            .iter()
            .map(|b| (b[2] - b[0]).max(b[3] - b[1]))
            .filter(|e| e.is_finite())
            .collect();
        ext.sort_by(|a, b| a.total_cmp(b));
        let cell = ext.get(ext.len() / 2).copied().unwrap_or(1.0).max(1e-6);
        let origin = [
            boxes.iter().map(|b| b[0]).fold(f64::INFINITY, f64::min),
            boxes.iter().map(|b| b[1]).fold(f64::INFINITY, f64::min),
        ];
        let mut index = BoxIndex {
            origin,
            cell,
            boxes: boxes.to_vec(),
            cells: HashMap::default(),
        };
        for (e, b) in boxes.iter().enumerate() {
            let (lo, hi) = (index.key(b[0], b[1]), index.key(b[2], b[3]));
            for x in lo.0..=hi.0 {
                for y in lo.1..=hi.1 {
                    index.cells.entry((x, y)).or_default().push(e);
                }
            }
        }
        index
    }

    fn key(&self, x: f64, y: f64) -> (i64, i64) {
        (
            ((x - self.origin[0]) / self.cell).floor() as i64,
            ((y - self.origin[1]) / self.cell).floor() as i64,
        )
    }

    /// The indices of the boxes that contain (x, y) (closed), in the order given.
    pub(crate) fn containing(&self, x: f64, y: f64) -> impl Iterator<Item = usize> + '_ {
        self.cells
            .get(&self.key(x, y))
            .map(|v| v.as_slice())
            .unwrap_or(&[])
            .iter()
            .copied()
            .filter(move |&k| {
                let b = &self.boxes[k];
                x >= b[0] && x <= b[2] && y >= b[1] && y <= b[3]
            })
    }

    /// True when any box overlaps [x0, y0, x1, y1].
    pub(crate) fn any_overlaps(&self, r: &[f64; 4]) -> bool {
        self.boxes
            .iter()
            .any(|b| b[0] <= r[2] && b[2] >= r[0] && b[1] <= r[3] && b[3] >= r[1])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_exactly_the_boxes_containing_a_point() {
        let idx = BoxIndex::new(&[
            [0.0, 0.0, 2.0, 2.0],
            [1.0, 1.0, 5.0, 3.0],
            [10.0, 10.0, 11.0, 11.0],
        ]);
        let at = |x, y| idx.containing(x, y).collect::<Vec<_>>();
        assert_eq!(at(1.5, 1.5), vec![0, 1]);
        assert_eq!(at(0.5, 0.5), vec![0]);
        assert_eq!(at(4.0, 2.5), vec![1]);
        assert_eq!(at(10.5, 11.0), vec![2]);
        assert!(at(7.0, 7.0).is_empty());
        assert!(idx.any_overlaps(&[4.5, 2.5, 6.0, 6.0]));
        assert!(!idx.any_overlaps(&[6.0, 4.0, 9.0, 9.0]));
    }
}
