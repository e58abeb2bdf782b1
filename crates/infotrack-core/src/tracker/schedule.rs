//! The multi-rate schedule: physics ticks at `physics_hz`, a filter step and a guidance
//! decision whenever their own period has elapsed. One copy of the arithmetic, so that the
//! simulator and the daemon step at exactly the same instants.

/// Loop rates of the tracker, Hz.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rates {
    /// Physics (tick) rate, Hz.
    pub physics_hz: f64,
    /// Filter (and measurement) rate, Hz.
    pub filter_hz: f64,
    /// Guidance rate, Hz.
    pub guidance_hz: f64,
}

/// What is due at one tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Due {
    /// Time of the tick since tracking began, s.
    pub t_s: f64,
    /// A filter step is due.
    pub filter: bool,
    /// A guidance decision is due.
    pub guidance: bool,
}

/// Counts ticks and decides what is due.
#[derive(Debug, Clone)]
pub struct Schedule {
    rates: Rates,
    tick: u64,
    next_filter: u64,
    next_guidance: u64,
}

impl Schedule {
    /// Before the first tick.
    pub fn new(rates: Rates) -> Self {
        Self {
            rates,
            tick: 0,
            next_filter: 1,
            next_guidance: 1,
        }
    }

    /// The rates.
    pub fn rates(&self) -> Rates {
        self.rates
    }

    /// Advances one physics tick and returns its time, without deciding anything (a tick
    /// on which the tracker cannot act: what was due stays due and is caught up later).
    pub fn skip(&mut self) -> f64 {
        self.tick += 1;
        self.tick as f64 * (1.0 / self.rates.physics_hz)
    }

    /// Advances one physics tick and says what is due at it. A step that is due is
    /// consumed: it will not be due again.
    pub fn advance(&mut self) -> Due {
        self.tick += 1;
        let t_s = self.tick as f64 * (1.0 / self.rates.physics_hz);
        let filter = t_s + 1e-9 >= self.next_filter as f64 / self.rates.filter_hz;
        if filter {
            self.next_filter += 1;
        }
        let guidance = t_s + 1e-9 >= self.next_guidance as f64 / self.rates.guidance_hz;
        if guidance {
            self.next_guidance += 1;
        }
        Due {
            t_s,
            filter,
            guidance,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lab_rates_give_three_filter_steps_and_one_decision_per_second() {
        let mut s = Schedule::new(Rates {
            physics_hz: 50.0,
            filter_hz: 3.0,
            guidance_hz: 1.0,
        });
        let due: Vec<Due> = (0..50).map(|_| s.advance()).collect();
        assert_eq!(due.iter().filter(|d| d.filter).count(), 3);
        assert_eq!(due.iter().filter(|d| d.guidance).count(), 1);
        assert!(due[49].guidance && (due[49].t_s - 1.0).abs() < 1e-12);
    }

    #[test]
    fn skipped_ticks_are_caught_up_one_step_per_tick() {
        let mut s = Schedule::new(Rates {
            physics_hz: 10.0,
            filter_hz: 5.0,
            guidance_hz: 1.0,
        });
        for _ in 0..10 {
            s.skip();
        }
        // Five filter periods elapsed unseen: they are caught up one per tick, so that by
        // t = 2 s all ten steps of those two seconds have run, and no more.
        let caught: Vec<bool> = (0..10).map(|_| s.advance().filter).collect();
        assert_eq!(caught, [true; 10]);
        assert!(!s.advance().filter);
    }
}
