//! The runs a pipeline has made, by run group (one group per data point when runs are per
//! abscissa, one group for all data points when a run returns the whole curve), each run with
//! its origin: the initial design, the test design, or a round of the adaptive engine.

use serde::Serialize;

use iuq_core::Outcome;

/// Where a run came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case", tag = "design")]
pub enum RunOrigin {
    /// The initial maximin Latin hypercube (a training run).
    Initial,
    /// The independent test design (scrambled Sobol'; never trained on).
    Test,
    /// Round `round` of the adaptive engine (a training run).
    Adaptive {
        /// The round, from 1.
        round: usize,
    },
    /// A posterior check made after round `round` that failed its test, its runs taken as
    /// training runs for the rounds that follow.
    Check {
        /// The round after which the check was made.
        round: usize,
    },
}

/// The successful runs of one output: inputs, outputs and computational stds.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct OutputRuns {
    /// Parameter vectors.
    pub x: Vec<Vec<f64>>,
    /// The output at each.
    pub y: Vec<f64>,
    /// Its computational std (0 when the run reported none).
    pub std: Vec<f64>,
}

/// Whole runs of a whole-curve model: each run's θ and all its outputs, in order.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Curves {
    /// Parameter vectors.
    pub inputs: Vec<Vec<f64>>,
    /// Every output of the run at each.
    pub outputs: Vec<Vec<f64>>,
}

/// The runs of one group, in the order they were requested.
#[derive(Debug, Clone, Default)]
pub struct GroupRuns {
    /// Parameter vectors θ.
    pub points: Vec<Vec<f64>>,
    /// What each run returned (outputs: the group's data points in order).
    pub outcomes: Vec<Outcome>,
    /// Where each run came from.
    pub origins: Vec<RunOrigin>,
}

impl GroupRuns {
    /// Add runs of one origin.
    pub fn extend(&mut self, origin: RunOrigin, points: Vec<Vec<f64>>, outcomes: Vec<Outcome>) {
        self.origins
            .extend(std::iter::repeat_n(origin, points.len()));
        self.points.extend(points);
        self.outcomes.extend(outcomes);
    }

    /// Runs of the group.
    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// Whether the group has no run.
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    fn successes(&self, output: usize, keep: impl Fn(RunOrigin) -> bool) -> OutputRuns {
        let mut runs = OutputRuns::default();
        for ((p, o), origin) in self.points.iter().zip(&self.outcomes).zip(&self.origins) {
            if !keep(*origin) {
                continue;
            }
            if let Ok(e) = o
                && let Some(&value) = e.outputs.get(output)
            {
                runs.x.push(p.clone());
                runs.y.push(value);
                runs.std.push(
                    e.computational_std
                        .as_ref()
                        .and_then(|s| s.get(output).copied())
                        .unwrap_or(0.0),
                );
            }
        }
        runs
    }

    /// The successful training runs' θ and whole output vectors (every output of a run, in
    /// order): the runs of a whole-curve model as a reduced basis takes them.
    pub fn training_curves(&self) -> Curves {
        let mut curves = Curves::default();
        for ((p, o), origin) in self.points.iter().zip(&self.outcomes).zip(&self.origins) {
            if let (Ok(e), false) = (o, *origin == RunOrigin::Test) {
                curves.inputs.push(p.clone());
                curves.outputs.push(e.outputs.clone());
            }
        }
        curves
    }

    /// The successful training runs (initial, adaptive and those of failed checks) of the
    /// group's output `output`.
    pub fn training(&self, output: usize) -> OutputRuns {
        self.successes(output, |o| o != RunOrigin::Test)
    }

    /// The successful test runs of the group's output `output`.
    pub fn test(&self, output: usize) -> OutputRuns {
        self.successes(output, |o| o == RunOrigin::Test)
    }

    /// Every run's θ and whether it failed (the failure classifier's training data).
    pub fn failure_labels(&self) -> (Vec<Vec<f64>>, Vec<bool>) {
        (
            self.points.clone(),
            self.outcomes.iter().map(Result::is_err).collect(),
        )
    }

    /// The reasons of the failed runs.
    pub fn failure_reasons(&self) -> Vec<String> {
        self.outcomes
            .iter()
            .filter_map(|o| o.as_ref().err().map(|f| f.reason.clone()))
            .collect()
    }

    /// Runs made by the adaptive engine (its rounds and the failed checks it trained on).
    pub fn adaptive_runs(&self) -> usize {
        self.origins
            .iter()
            .filter(|o| matches!(o, RunOrigin::Adaptive { .. } | RunOrigin::Check { .. }))
            .count()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use iuq_core::{Evaluation, EvaluationFailure};

    #[test]
    fn training_and_test_sets_and_failures() {
        let mut g = GroupRuns::default();
        g.extend(
            RunOrigin::Initial,
            vec![vec![0.0], vec![1.0]],
            vec![
                Ok(Evaluation::with_std(vec![1.0, 2.0], vec![0.1, 0.2])),
                Err(EvaluationFailure::new("boom")),
            ],
        );
        g.extend(
            RunOrigin::Test,
            vec![vec![0.5]],
            vec![Ok(Evaluation::new(vec![3.0, 4.0]))],
        );
        g.extend(
            RunOrigin::Adaptive { round: 1 },
            vec![vec![0.25]],
            vec![Ok(Evaluation::new(vec![5.0, 6.0]))],
        );
        let t = g.training(1);
        assert_eq!(t.x, vec![vec![0.0], vec![0.25]]);
        assert_eq!(t.y, vec![2.0, 6.0]);
        assert_eq!(t.std, vec![0.2, 0.0]);
        assert_eq!(g.test(0).y, vec![3.0]);
        assert_eq!(g.failure_labels().1, vec![false, true, false, false]);
        assert_eq!(g.failure_reasons(), vec!["boom".to_string()]);
        assert_eq!(g.adaptive_runs(), 1);
        assert_eq!(g.len(), 4);
    }
}
