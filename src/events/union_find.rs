//! Disjoint-set forest (Tarjan 1975) with path halving and union by index: the root of
//! every set is its smallest element, so the result does not depend on the order in which
//! unions arrive (tiles may be merged in any order, by any number of threads).

/// Union-find over dense indices `0..n` (n < 2³²: four bytes an element, as the events unit
/// holds one over a pair's kept core points).
#[derive(Debug, Clone, Default)]
pub(crate) struct UnionFind {
    parent: Vec<u32>,
}

impl UnionFind {
    /// `n` singleton sets.
    pub(crate) fn new(n: usize) -> Self {
        let mut sets = UnionFind::default();
        sets.grow(n);
        sets
    }

    /// Add singletons until there are `n` elements (fewer: nothing).
    pub(crate) fn grow(&mut self, n: usize) {
        assert!(n <= u32::MAX as usize, "union-find over {n} elements");
        let len = self.parent.len() as u32;
        self.parent.extend(len..n as u32);
    }

    /// Number of elements.
    #[cfg(test)]
    pub(crate) fn len(&self) -> usize {
        self.parent.len()
    }

    /// The root (smallest element) of `x`'s set.
    pub(crate) fn find(&mut self, x: usize) -> usize {
        let mut x = x as u32;
        while self.parent[x as usize] != x {
            // Path halving: point to the grandparent while walking up.
            self.parent[x as usize] = self.parent[self.parent[x as usize] as usize];
            x = self.parent[x as usize];
        }
        x as usize
    }

    /// Merge the sets of `a` and `b`; the smaller root becomes the root.
    pub(crate) fn union(&mut self, a: usize, b: usize) {
        let (ra, rb) = (self.find(a), self.find(b));
        if ra < rb {
            self.parent[rb] = ra as u32;
        } else if rb < ra {
            self.parent[ra] = rb as u32;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn roots_are_smallest_members() {
        let mut uf = UnionFind::new(6);
        uf.union(4, 5);
        uf.union(5, 2);
        uf.union(0, 1);
        assert_eq!(uf.find(5), 2);
        assert_eq!(uf.find(4), 2);
        assert_eq!(uf.find(1), 0);
        assert_eq!(uf.find(3), 3);
        uf.union(1, 4);
        assert_eq!(uf.find(2), 0);
        // Grown: the new elements are singletons, the old sets kept.
        uf.grow(8);
        assert_eq!((uf.len(), uf.find(6), uf.find(7), uf.find(5)), (8, 6, 7, 0));
        uf.union(7, 3);
        assert_eq!(uf.find(7), 3);
    }
}
