//! Disjoint sets over `0..n`: the components of faces, corners or vertices that the mesh core,
//! the texture islands and fl-mesh join. Union puts the larger root under the smaller, so a
//! set's root is always its smallest element, whatever the order of the unions; callers may
//! rely on that (a component is named by its first face). Our own, not a crate's: it is this
//! one invariant in twenty lines, which the general crates (ranked unions) do not keep.

/// Disjoint sets over `0..n`, each rooted at its smallest element.
#[derive(Debug, Clone, Default)]
pub struct DisjointSets {
    parent: Vec<u32>,
}

impl DisjointSets {
    /// `n` singletons.
    pub fn new(n: usize) -> Self {
        let mut s = DisjointSets::default();
        s.reset(n);
        s
    }

    /// Back to `n` singletons, keeping the allocation.
    pub fn reset(&mut self, n: usize) {
        self.parent.clear();
        self.parent.extend(0..n as u32);
    }

    /// The root (smallest element) of `x`'s set, halving the path on the way.
    pub fn find(&mut self, mut x: u32) -> u32 {
        while self.parent[x as usize] != x {
            let up = self.parent[self.parent[x as usize] as usize];
            self.parent[x as usize] = up;
            x = up;
        }
        x
    }

    /// Join the sets of `a` and `b`; whether they were apart.
    pub fn union(&mut self, a: u32, b: u32) -> bool {
        let (ra, rb) = (self.find(a), self.find(b));
        if ra == rb {
            return false;
        }
        self.parent[ra.max(rb) as usize] = ra.min(rb);
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn roots_are_the_smallest_elements_whatever_the_order() {
        let mut s = DisjointSets::new(8);
        assert!(s.union(7, 5));
        assert!(s.union(5, 6));
        assert!(s.union(3, 7));
        assert!(!s.union(6, 3));
        assert!(s.union(1, 2));
        let roots: Vec<u32> = (0..8).map(|x| s.find(x)).collect();
        assert_eq!(roots, [0, 1, 1, 3, 4, 3, 3, 3]);
        s.reset(3);
        assert_eq!((0..3).map(|x| s.find(x)).collect::<Vec<_>>(), [0, 1, 2]);
    }
}
