//! A batch of position tracks, stored contiguously as `[n][k_in][2]` f64, oldest first: the
//! layout a learned model takes as input.

use crate::world::geometry::Enu2;

/// `n` tracks of `k_in` positions each (world ENU, metres), oldest first.
#[derive(Debug, Clone, PartialEq)]
pub struct Histories {
    n: usize,
    k_in: usize,
    data: Vec<f64>,
}

impl Histories {
    /// `n` tracks of `k_in` positions, all at the origin.
    pub fn new(n: usize, k_in: usize) -> Self {
        Self {
            n,
            k_in,
            data: vec![0.0; n * k_in * 2],
        }
    }

    /// Number of tracks.
    pub fn len(&self) -> usize {
        self.n
    }

    /// Whether there are no tracks.
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    /// Positions per track.
    pub fn k_in(&self) -> usize {
        self.k_in
    }

    /// The whole buffer, `[n][k_in][2]`.
    pub fn as_slice(&self) -> &[f64] {
        &self.data
    }

    /// Track `i` as `[x0, y0, x1, y1, ...]`, oldest first.
    #[inline]
    pub fn track(&self, i: usize) -> &[f64] {
        let s = 2 * self.k_in;
        &self.data[i * s..(i + 1) * s]
    }

    /// Mutable track `i`.
    #[inline]
    pub fn track_mut(&mut self, i: usize) -> &mut [f64] {
        let s = 2 * self.k_in;
        &mut self.data[i * s..(i + 1) * s]
    }

    /// Position `t` (0 = oldest) of track `i`.
    #[inline]
    pub fn at(&self, i: usize, t: usize) -> Enu2 {
        let tr = self.track(i);
        Enu2::new(tr[2 * t], tr[2 * t + 1])
    }

    /// Newest position of track `i`.
    #[inline]
    pub fn newest(&self, i: usize) -> Enu2 {
        self.at(i, self.k_in - 1)
    }

    /// Shifts every track one step into the past and appends `next[i]` to track `i`.
    pub fn push(&mut self, next: &[Enu2]) {
        assert_eq!(next.len(), self.n, "one new position per track");
        let s = 2 * self.k_in;
        for (i, p) in next.iter().enumerate() {
            let tr = &mut self.data[i * s..(i + 1) * s];
            tr.copy_within(2.., 0);
            tr[s - 2] = p.x;
            tr[s - 1] = p.y;
        }
    }

    /// Adds `offset` to every position of track `i` (moves the track, keeps its shape).
    pub fn translate(&mut self, i: usize, offset: &Enu2) {
        for xy in self.track_mut(i).chunks_exact_mut(2) {
            xy[0] += offset.x;
            xy[1] += offset.y;
        }
    }

    /// Tracks `indices` of `self`, in that order, copied into `out` (resized as needed).
    pub fn gather_into(&self, indices: &[usize], out: &mut Histories) {
        let s = 2 * self.k_in;
        out.n = indices.len();
        out.k_in = self.k_in;
        out.data.resize(indices.len() * s, 0.0);
        for (dst, &src) in out.data.chunks_exact_mut(s).zip(indices) {
            dst.copy_from_slice(&self.data[src * s..(src + 1) * s]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn push_shifts_oldest_out() {
        let mut h = Histories::new(2, 3);
        for k in 1..=4 {
            let p = [Enu2::new(k as f64, 0.0), Enu2::new(0.0, -(k as f64))];
            h.push(&p);
        }
        assert_eq!(h.at(0, 0), Enu2::new(2.0, 0.0));
        assert_eq!(h.newest(0), Enu2::new(4.0, 0.0));
        assert_eq!(h.newest(1), Enu2::new(0.0, -4.0));
    }

    #[test]
    fn gather_copies_whole_tracks() {
        let mut h = Histories::new(3, 2);
        h.push(&[
            Enu2::new(1.0, 1.0),
            Enu2::new(2.0, 2.0),
            Enu2::new(3.0, 3.0),
        ]);
        let mut out = Histories::new(0, 2);
        h.gather_into(&[2, 2, 0], &mut out);
        assert_eq!(out.len(), 3);
        assert_eq!(out.newest(0), Enu2::new(3.0, 3.0));
        assert_eq!(out.newest(2), Enu2::new(1.0, 1.0));
        assert_eq!(out.track(1), h.track(2));
    }
}
