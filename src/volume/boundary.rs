//! Closed loops from the directed boundary edges of a planar subdivision.
//!
//! Both the outline of a region (its cells' edges that no other region cell shares) and the walls
//! of a solid (the top's edges that no other top face shares) are sets of directed edges with the
//! region on their left. Where two parts of a region touch at one corner only (a "pinch": two cells
//! meeting diagonally), a vertex has several incoming and outgoing edges; each incoming edge is
//! paired with the outgoing edge met first when turning clockwise from it, which keeps the two
//! parts separate loops (the region between an incoming and its outgoing edge is the region's
//! corner at that vertex).

use rustc_hash::FxHashMap as HashMap;

/// For every edge `edges[k] = (a, b)`, the index of the edge that follows it on its loop (an edge
/// leaving `b`). `None` for an edge with no successor (an open chain: the edges do not form
/// closed loops). `pos` gives a vertex's (u, v) position, for the pinch rule.
pub(crate) fn successors(
    edges: &[(u32, u32)],
    pos: impl Fn(u32) -> [f64; 2],
) -> Vec<Option<usize>> {
    let mut leaving: HashMap<u32, Vec<usize>> = HashMap::default();
    for (k, &(a, _)) in edges.iter().enumerate() {
        leaving.entry(a).or_default().push(k);
    }
    let angle = |from: u32, to: u32| {
        let (p, q) = (pos(from), pos(to));
        (q[1] - p[1]).atan2(q[0] - p[0])
    };
    edges
        .iter()
        .map(|&(a, b)| {
            let out = leaving.get(&b)?;
            if out.len() == 1 {
                return Some(out[0]);
            }
            // Clockwise turn from the direction back to `a` to each outgoing direction.
            let back = angle(b, a);
            out.iter().copied().min_by(|&x, &y| {
                let turn = |k: usize| {
                    let t = (back - angle(b, edges[k].1)).rem_euclid(std::f64::consts::TAU);
                    if t == 0.0 {
                        std::f64::consts::TAU
                    } else {
                        t
                    }
                };
                turn(x).total_cmp(&turn(y)).then(x.cmp(&y))
            })
        })
        .collect()
}

/// The closed loops the edges form, each as its vertices in order (first vertex not repeated),
/// in a deterministic order (by their first edge). Edges on open chains are left out.
pub(crate) fn loops(edges: &[(u32, u32)], pos: impl Fn(u32) -> [f64; 2]) -> Vec<Vec<u32>> {
    let next = successors(edges, pos);
    let mut seen = vec![false; edges.len()];
    let mut out = Vec::new();
    for start in 0..edges.len() {
        if seen[start] {
            continue;
        }
        let mut ring = Vec::new();
        let mut k = start;
        let closed = loop {
            if seen[k] {
                break k == start;
            }
            seen[k] = true;
            ring.push(edges[k].0);
            match next[k] {
                Some(n) => k = n,
                None => break false,
            }
        };
        if closed && ring.len() >= 3 {
            out.push(ring);
        }
    }
    out
}

/// Twice the signed area of a ring (positive counter-clockwise).
pub(crate) fn signed_area2(ring: &[[f64; 2]]) -> f64 {
    let n = ring.len();
    (0..n)
        .map(|i| {
            let (p, q) = (ring[i], ring[(i + 1) % n]);
            p[0] * q[1] - q[0] * p[1]
        })
        .sum()
}

/// Is `p` strictly inside `ring` (even–odd rule)? Points on the ring may go either way.
pub(crate) fn contains(ring: &[[f64; 2]], p: [f64; 2]) -> bool {
    let n = ring.len();
    let mut inside = false;
    for i in 0..n {
        let (a, b) = (ring[i], ring[(i + 1) % n]);
        if (a[1] > p[1]) != (b[1] > p[1]) {
            let x = a[0] + (p[1] - a[1]) / (b[1] - a[1]) * (b[0] - a[0]);
            if p[0] < x {
                inside = !inside;
            }
        }
    }
    inside
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_square_is_one_loop() {
        let pos = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
        let edges = [(2, 3), (0, 1), (3, 0), (1, 2)];
        let l = loops(&edges, |v| pos[v as usize]);
        assert_eq!(l, vec![vec![2, 3, 0, 1]]);
        let ring: Vec<[f64; 2]> = l[0].iter().map(|&v| pos[v as usize]).collect();
        assert_eq!(signed_area2(&ring), 2.0);
        assert!(contains(&ring, [0.5, 0.5]) && !contains(&ring, [1.5, 0.5]));
    }

    #[test]
    fn two_cells_touching_at_a_corner_stay_two_loops() {
        // Cells [0,1]² and [1,2]×[1,2] share vertex 4 = (1, 1).
        let pos = [
            [0.0, 0.0],
            [1.0, 0.0],
            [0.0, 1.0],
            [2.0, 1.0],
            [1.0, 1.0],
            [1.0, 2.0],
            [2.0, 2.0],
        ];
        let edges = [
            (0, 1),
            (1, 4),
            (4, 2),
            (2, 0),
            (4, 3),
            (3, 6),
            (6, 5),
            (5, 4),
        ];
        let mut l = loops(&edges, |v| pos[v as usize]);
        l.sort();
        assert_eq!(l.len(), 2, "{l:?}");
        for ring in &l {
            let r: Vec<[f64; 2]> = ring.iter().map(|&v| pos[v as usize]).collect();
            assert_eq!(signed_area2(&r), 2.0, "{ring:?}");
        }
    }

    #[test]
    fn open_chains_are_left_out() {
        let pos = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]];
        assert!(loops(&[(0, 1), (1, 2)], |v| pos[v as usize]).is_empty());
    }
}
