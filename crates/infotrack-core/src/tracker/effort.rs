//! The guidance's effort under a compute budget (the daemon's `guidance_budget_ms`): a
//! decision that takes most of its budget halves the hypotheses EER weighs (N_H) for the
//! next ones, down to an eighth; a run of quick decisions doubles them again. A slow
//! companion computer then plans with fewer hypotheses on purpose, and says so, instead of
//! skipping decisions. Without a budget (the simulator) the effort never changes.

/// What one decision's compute time did to the effort.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EffortChange {
    /// Lowered to 1 / 2^level of the hypotheses.
    Lowered {
        /// The new level (1 to [`MAX_LEVEL`]).
        level: u8,
    },
    /// Raised back towards the full count.
    Raised {
        /// The new level (0: every configured hypothesis).
        level: u8,
    },
}

/// The most the effort is lowered: an eighth of the hypotheses.
pub const MAX_LEVEL: u8 = 3;
/// A decision over this share of its budget lowers the effort.
pub const SLOW_SHARE: f64 = 0.8;
/// A decision under this share of its budget counts as quick.
pub const QUICK_SHARE: f64 = 0.25;
/// Quick decisions in a row that raise the effort a level.
pub const QUICK_RUN: u32 = 20;

/// The effort level and the run of quick decisions behind it.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Effort {
    level: u8,
    quick_run: u32,
}

impl Effort {
    /// The level: EER weighs 1 / 2^level of its hypotheses.
    pub fn level(&self) -> u8 {
        self.level
    }

    /// The divisor of the hypotheses EER weighs.
    pub fn divisor(&self) -> usize {
        1 << self.level
    }

    /// A decision took `compute_ms` of `budget_ms`.
    pub fn note(&mut self, compute_ms: f64, budget_ms: f64) -> Option<EffortChange> {
        if compute_ms > SLOW_SHARE * budget_ms {
            self.quick_run = 0;
            if self.level < MAX_LEVEL {
                self.level += 1;
                return Some(EffortChange::Lowered { level: self.level });
            }
        } else if compute_ms < QUICK_SHARE * budget_ms {
            self.quick_run += 1;
            if self.quick_run >= QUICK_RUN && self.level > 0 {
                self.quick_run = 0;
                self.level -= 1;
                return Some(EffortChange::Raised { level: self.level });
            }
        } else {
            self.quick_run = 0;
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slow_decisions_lower_the_effort_to_an_eighth_and_quick_runs_raise_it_again() {
        let mut e = Effort::default();
        assert_eq!(
            e.note(250.0, 300.0),
            Some(EffortChange::Lowered { level: 1 })
        );
        assert_eq!(
            e.note(400.0, 300.0),
            Some(EffortChange::Lowered { level: 2 })
        );
        assert_eq!(
            e.note(400.0, 300.0),
            Some(EffortChange::Lowered { level: 3 })
        );
        assert_eq!(e.note(400.0, 300.0), None, "an eighth at most");
        assert_eq!(e.divisor(), 8);
        for _ in 1..QUICK_RUN {
            assert_eq!(e.note(10.0, 300.0), None);
        }
        assert_eq!(e.note(10.0, 300.0), Some(EffortChange::Raised { level: 2 }));
        // A middling decision breaks the run of quick ones.
        for _ in 1..QUICK_RUN {
            e.note(10.0, 300.0);
        }
        assert_eq!(e.note(150.0, 300.0), None);
        assert_eq!(e.note(10.0, 300.0), None);
        assert_eq!(e.level(), 2);
    }
}
