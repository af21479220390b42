//! What the pipeline's stages compute on: the study's data, the initial and test designs mapped
//! through the priors, and the Sobol' options.

use iuq_core::ParameterSpace;
use iuq_doe::{LhsMethod, Scrambling, latin_hypercube, sobol_points};
use iuq_sensitivity::{IntervalMethod, SensitivityOptions};

use super::settings::PipelineSettings;
use crate::error::{Result, StudyError, input_error};
use crate::likelihood_section::{DataLikelihood, LikelihoodSection, parse_likelihood};
use crate::study::Study;

/// The study's data (the pipeline calibrates a model on data).
pub(super) fn study_data(study: &Study) -> Result<DataLikelihood> {
    let file = study.path.display();
    match parse_likelihood(study)? {
        LikelihoodSection::Data(data) if data.prediction.is_none() => Ok(data),
        _ => Err(input_error(format!(
            "{file}: section `[likelihood]`: the pipeline calibrates the model on data: give `data = {{ file, x, y, ... }}` without `prediction`"
        ))),
    }
}

/// The initial points of run group g: a maximin Latin hypercube mapped through the priors.
pub(super) fn training_points(
    space: &ParameterSpace,
    settings: &PipelineSettings,
    g: usize,
) -> Result<Vec<Vec<f64>>> {
    let unit = latin_hypercube(
        settings.training_runs,
        space.dimension(),
        LhsMethod::Maximin {
            candidates: settings.maximin_candidates,
        },
        settings.training_seed.wrapping_add(g as u64),
    )?;
    unit.iter()
        .map(|u| space.from_unit_cube(u).map_err(StudyError::from))
        .collect()
}

/// The test points (the same in every group): scrambled Sobol' points through the priors.
pub(super) fn test_points(
    space: &ParameterSpace,
    settings: &PipelineSettings,
) -> Result<Vec<Vec<f64>>> {
    if settings.test_runs == 0 {
        return Ok(Vec::new());
    }
    let unit = sobol_points(
        space.dimension(),
        settings.test_runs,
        Scrambling::LinearMatrixWithShift {
            seed: settings.test_seed,
            replicate: 0,
        },
    )?;
    unit.iter()
        .map(|u| space.from_unit_cube(u).map_err(StudyError::from))
        .collect()
}

/// Sobol' options of the pipeline with `n` base points.
pub(super) fn sobol_options(settings: &PipelineSettings, n: usize) -> SensitivityOptions {
    SensitivityOptions {
        base_points: n,
        seed: settings.sobol_seed,
        interval: IntervalMethod::Bootstrap {
            resamples: settings.resamples,
        },
        confidence_level: settings.confidence,
        ..Default::default()
    }
}
