//! The one keeper of a time budget, for the commands that measure as much as their budget
//! allows: `profile` (its variant rows and its environment rows) and `stability` (its
//! cells). It knows the time left, learns what each kind of step costs from the steps it
//! has measured, says whether the next step fits, and at the end whether the budget was
//! kept: within [`KEPT_WITHIN`] of it, or a line that names the step that broke it.
//!
//! A kind of step (a key `K`: a profile row's frame, a table's `(w, λ)` plane, an
//! environment map of one variant, a stability cell of one variant and evaluator) costs
//! `fixed + per_unit·units` seconds. Its two numbers come from a prior until a step of that
//! kind is measured; then from the measured steps by least squares, or, while every step
//! measured has the same size, from the cost already known (a split measured another way,
//! [`Keeper::split`], or the prior) scaled to them.

use std::time::Instant;

/// The budget counts as kept while the whole run takes at most this much more than it.
pub const KEPT_WITHIN: f64 = 0.2;

/// What a kind of step costs (s): `fixed_s + per_unit_s·units`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Cost {
    pub fixed_s: f64,
    pub per_unit_s: f64,
}

impl Cost {
    pub fn at(&self, units: f64) -> f64 {
        self.fixed_s + self.per_unit_s * units
    }

    /// The cost fitted to `(units, seconds)` steps: least squares over steps of different
    /// sizes. Steps of one size only say how much slower or faster than `known` the work
    /// goes, not which part: both of `known`'s parts are scaled by it (without a `known`
    /// cost, the steps' mean is a rate, or a fixed cost for steps of no units).
    fn fit(steps: &[(f64, f64)], known: Cost) -> Cost {
        let n = steps.len() as f64;
        let mean = |f: &dyn Fn(&(f64, f64)) -> f64| steps.iter().map(f).sum::<f64>() / n;
        let (mu, ms) = (mean(&|s| s.0), mean(&|s| s.1));
        let var = mean(&|s| (s.0 - mu) * (s.0 - mu));
        if var > 1e-12 * mu.max(1.0) * mu.max(1.0) {
            let cov = mean(&|s| (s.0 - mu) * (s.1 - ms));
            let per_unit_s = (cov / var).max(0.0);
            return Cost {
                fixed_s: (ms - per_unit_s * mu).max(0.0),
                per_unit_s,
            };
        }
        let expected = known.at(mu);
        if expected > 0.0 {
            let scale = ms / expected;
            return Cost {
                fixed_s: known.fixed_s * scale,
                per_unit_s: known.per_unit_s * scale,
            };
        }
        if mu <= 0.0 {
            return Cost {
                fixed_s: ms,
                per_unit_s: 0.0,
            };
        }
        Cost {
            fixed_s: 0.0,
            per_unit_s: ms / mu,
        }
    }
}

/// One kind of step's record: its prior or measured split, and its measured steps.
#[derive(Debug, Clone)]
struct Kind<K> {
    key: K,
    /// The cost before any step (a prior), or a split measured another way.
    known: Option<Cost>,
    /// Measured steps: `(units, seconds)`.
    steps: Vec<(f64, f64)>,
}

/// A step the keeper timed, to say afterwards what broke the budget.
#[derive(Debug, Clone)]
struct Timed {
    name: String,
    estimated_s: Option<f64>,
    took_s: f64,
}

/// Whether a step fits what is left of the budget.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Fits {
    /// Run it (no budget, or it fits, or it must run).
    Yes,
    /// Leave it out: its estimate is over what is left.
    No { estimated_s: f64, left_s: f64 },
}

/// A budget in progress (module docs).
#[derive(Debug, Clone)]
pub struct Keeper<K> {
    start: Instant,
    total_s: Option<f64>,
    kinds: Vec<Kind<K>>,
    timed: Vec<Timed>,
}

impl<K: PartialEq + Clone> Keeper<K> {
    /// A budget of `total_s` (none: every step runs) counted from `start`.
    pub fn new(start: Instant, total_s: Option<f64>) -> Self {
        Self {
            start,
            total_s,
            kinds: Vec::new(),
            timed: Vec::new(),
        }
    }

    /// Seconds left of the budget (0 once spent); `None` without a budget.
    pub fn left_s(&self) -> Option<f64> {
        self.total_s
            .map(|t| (t - self.start.elapsed().as_secs_f64()).max(0.0))
    }

    fn kind(&mut self, key: &K) -> &mut Kind<K> {
        match self.kinds.iter().position(|k| k.key == *key) {
            Some(i) => &mut self.kinds[i],
            None => {
                self.kinds.push(Kind {
                    key: key.clone(),
                    known: None,
                    steps: Vec::new(),
                });
                self.kinds.last_mut().expect("just pushed")
            }
        }
    }

    /// What `key` costs before any of its steps is measured.
    pub fn prior(&mut self, key: &K, cost: Cost) {
        let kind = self.kind(key);
        if kind.known.is_none() {
            kind.known = Some(cost);
        }
    }

    /// A cost of `key` measured another way (an environment map's fixed part and its rate
    /// per sample, from its wall and GPU times): it replaces what the steps so far said.
    pub fn split(&mut self, key: &K, cost: Cost) {
        let kind = self.kind(key);
        kind.known = Some(cost);
        kind.steps.clear();
    }

    /// A measured step of `key`: `units` of work in `seconds`.
    pub fn learn(&mut self, key: &K, units: f64, seconds: f64) {
        if units.is_finite() && seconds.is_finite() && seconds >= 0.0 {
            self.kind(key).steps.push((units.max(0.0), seconds));
        }
    }

    /// What `key` costs now; `None` before a prior or a step.
    pub fn cost(&self, key: &K) -> Option<Cost> {
        let kind = self.kinds.iter().find(|k| k.key == *key)?;
        let known = kind.known.unwrap_or_default();
        match kind.steps.is_empty() {
            true => kind.known,
            false => Some(Cost::fit(&kind.steps, known)),
        }
    }

    /// The estimated seconds of a step of `key` with `units`; `None` before a prior or a
    /// step of it.
    pub fn estimate_s(&self, key: &K, units: f64) -> Option<f64> {
        self.cost(key).map(|c| c.at(units))
    }

    /// [`Self::estimate_s`], or, for a kind not measured yet, the mean first step of the
    /// measured kinds `like` picks (what a first step costs, its set-up included).
    pub fn estimate_like(&self, key: &K, units: f64, like: impl Fn(&K) -> bool) -> Option<f64> {
        if let Some(e) = self.estimate_s(key, units) {
            return Some(e);
        }
        let firsts: Vec<f64> = self
            .kinds
            .iter()
            .filter(|k| like(&k.key))
            .filter_map(|k| k.steps.first().map(|s| s.1))
            .collect();
        (!firsts.is_empty()).then(|| firsts.iter().sum::<f64>() / firsts.len() as f64)
    }

    /// Whether a step estimated at `estimated_s` (`None`: unknown) fits what is left. An
    /// unknown cost fits while time is left.
    pub fn fits(&self, estimated_s: Option<f64>) -> Fits {
        let Some(left_s) = self.left_s() else {
            return Fits::Yes;
        };
        match estimated_s {
            Some(e) if e > left_s => Fits::No {
                estimated_s: e,
                left_s,
            },
            None if left_s <= 0.0 => Fits::No {
                estimated_s: 0.0,
                left_s,
            },
            _ => Fits::Yes,
        }
    }

    /// Records a step that ran: its name, its estimate when it was let in, its time.
    pub fn timed(&mut self, name: &str, estimated_s: Option<f64>, took_s: f64) {
        self.timed.push(Timed {
            name: name.to_string(),
            estimated_s,
            took_s,
        });
    }

    /// After the run (`elapsed_s` in all): `None` when the budget was kept (within
    /// [`KEPT_WITHIN`]) or there was none; else a line that says by how much it was not and
    /// which step broke it (the one furthest over its estimate, or the longest).
    pub fn broken(&self, what: &str, elapsed_s: f64) -> Option<String> {
        let total = self.total_s?;
        if elapsed_s <= (1.0 + KEPT_WITHIN) * total {
            return None;
        }
        let over = |t: &Timed| t.took_s - t.estimated_s.unwrap_or(0.0);
        let worst = self.timed.iter().max_by(|a, b| over(a).total_cmp(&over(b)));
        let why = match worst {
            Some(t) => match t.estimated_s {
                Some(e) => format!(
                    "{} took {:.1} s against its estimated {e:.1} s",
                    t.name, t.took_s
                ),
                None => format!(
                    "{} took {:.1} s, run before anything could estimate it",
                    t.name, t.took_s
                ),
            },
            None => "no step was timed".to_string(),
        };
        Some(format!(
            "{what} took {elapsed_s:.0} s of its {total:.0} s budget ({:.0} % over): {why}; \
             the budget leaves out whole steps only",
            100.0 * (elapsed_s / total - 1.0)
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_cost_is_fitted_to_steps_of_different_sizes() {
        let mut k = Keeper::<&str>::new(Instant::now(), Some(60.0));
        assert_eq!(k.estimate_s(&"map", 10.0), None);
        k.prior(
            &"map",
            Cost {
                fixed_s: 0.5,
                per_unit_s: 1.0,
            },
        );
        assert_eq!(k.estimate_s(&"map", 2.0), Some(2.5));
        // One size: the prior scaled to it (10.5 s expected, 2.1 s taken: a fifth).
        k.learn(&"map", 10.0, 2.1);
        assert!((k.estimate_s(&"map", 20.0).unwrap() - 4.1).abs() < 1e-12);
        k.learn(&"map", 10.0, 2.9);
        assert!((k.estimate_s(&"map", 10.0).unwrap() - 2.5).abs() < 1e-12);
        // Two sizes: the line through them (the mean of the first size and the new one).
        k.learn(&"map", 30.0, 4.5);
        let c = k.cost(&"map").unwrap();
        assert!(
            (c.per_unit_s - 0.1).abs() < 1e-12 && (c.fixed_s - 1.5).abs() < 1e-12,
            "{c:?}"
        );
        // A split measured another way replaces the steps.
        k.split(
            &"map",
            Cost {
                fixed_s: 0.1,
                per_unit_s: 0.01,
            },
        );
        assert_eq!(k.estimate_s(&"map", 100.0), Some(1.1));
        // Steps of no units are a fixed cost: their mean.
        k.learn(&"setup", 0.0, 1.0);
        k.learn(&"setup", 0.0, 3.0);
        assert_eq!(k.estimate_s(&"setup", 0.0), Some(2.0));
    }

    #[test]
    fn an_unmeasured_kind_is_estimated_from_the_first_steps_of_its_like() {
        let mut k = Keeper::<(u8, u8)>::new(Instant::now(), None);
        k.learn(&(1, 0), 1.0, 4.0);
        k.learn(&(1, 0), 1.0, 1.0);
        k.learn(&(2, 1), 1.0, 9.0);
        assert_eq!(k.estimate_like(&(3, 0), 1.0, |key| key.1 == 0), Some(4.0));
        assert_eq!(k.estimate_like(&(1, 0), 1.0, |_| true), Some(2.5));
        assert_eq!(k.estimate_like(&(3, 5), 1.0, |key| key.1 == 5), None);
    }

    #[test]
    fn a_step_fits_what_is_left_and_a_broken_budget_names_its_cause() {
        let k = Keeper::<u8>::new(Instant::now(), Some(10.0));
        assert_eq!(k.fits(Some(5.0)), Fits::Yes);
        assert!(matches!(k.fits(Some(11.0)), Fits::No { .. }));
        assert_eq!(k.fits(None), Fits::Yes);
        let ago = std::time::Duration::from_secs(20);
        let spent = Keeper::<u8>::new(Instant::now() - ago, Some(10.0));
        assert_eq!(spent.left_s(), Some(0.0));
        assert!(matches!(spent.fits(None), Fits::No { .. }));
        assert_eq!(
            Keeper::<u8>::new(Instant::now(), None).fits(Some(1e9)),
            Fits::Yes
        );

        let mut k = Keeper::<u8>::new(Instant::now(), Some(10.0));
        k.timed("row a", Some(2.0), 2.5);
        k.timed("row b", Some(1.0), 9.0);
        assert_eq!(k.broken("profile", 11.9), None, "within 20 %");
        let line = k.broken("profile", 13.0).unwrap();
        assert!(
            line.contains("30 % over")
                && line.contains("row b took 9.0 s against its estimated 1.0 s"),
            "{line}"
        );
        assert_eq!(
            Keeper::<u8>::new(Instant::now(), None).broken("x", 1e9),
            None
        );
    }
}
