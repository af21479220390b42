//! The cell over a whole shear run, for pictures: its elongation index against the strain from
//! the start (the measuring window marked), and its final shape seen in the shear plane
//! (flow–gradient, x–y in HemoCell's frame: the contour the elongation index is measured on,
//! with its fitted ellipse) and from the side (flow–vorticity, x–z).
//!
//! The run is [`crate::run_shear`]'s, bit for bit (its elongation index is the same number); the
//! shape is only read every `every` steps to measure the trace. Early in a run the projection
//! may admit no ellipse (a disk seen edge-on): such points are left out of the trace.

use serde::{Deserialize, Serialize};

use crate::ellipse::{contour_points, elongation_index, fit_ellipse};
use crate::error::Result;
use crate::protocol::{ShearExperiment, run_shear_observed};
use crate::units::LatticeUnits;

/// A shear run told in pictures (lengths in µm, centred on the shape's centroid).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ShearPortrait {
    /// Shear stress in Pa.
    pub stress: f64,
    /// The run's elongation index (mean over the measuring window's frames) and its std.
    pub elongation_index: (f64, f64),
    /// (strain γ̇t, elongation index) through the run.
    pub trace: Vec<(f64, f64)>,
    /// The measuring window in strain units (start, end).
    pub window: (f64, f64),
    /// The last frame's contour in the shear plane (x flow, y gradient).
    pub outline: Vec<[f64; 2]>,
    /// Its fitted ellipse: centre x, centre y, semi-major, semi-minor, angle of the major axis
    /// to the flow (radians).
    pub ellipse: [f64; 5],
    /// The last frame's contour seen from the side (x flow, z vorticity).
    pub side: Vec<[f64; 2]>,
}

/// Run `experiment` and portray it, measuring the elongation index at about `trace_points`
/// evenly spaced steps.
pub fn shear_portrait(experiment: &ShearExperiment, trace_points: usize) -> Result<ShearPortrait> {
    let setup = experiment.setup();
    let every = (setup.t_max / trace_points.max(1) as u64).max(1);
    let rate = setup.lattice_shear_rate;
    let bin_width = setup.bin_width;
    let mut trace = Vec::new();
    let result = run_shear_observed(experiment, every, &mut |step, vertices| {
        if let Ok(el) = elongation_index(vertices, bin_width) {
            trace.push((step as f64 * rate, el));
        }
    })?;
    let um = LatticeUnits::reference().dx * 1e6;
    let Some(last) = result.frames.last() else {
        return Err(crate::RbcError::InvalidData(
            "the run recorded no frame".into(),
        ));
    };
    let n = last.vertices.len().max(1) as f64;
    let centroid: [f64; 3] =
        std::array::from_fn(|k| last.vertices.iter().map(|v| v[k]).sum::<f64>() / n);
    let centred: Vec<[f64; 3]> = last
        .vertices
        .iter()
        .map(|v| std::array::from_fn(|k| (v[k] - centroid[k]) * um))
        .collect();
    let outline = contour_points(&centred, bin_width * um);
    let e = fit_ellipse(&outline)?;
    let side_view: Vec<[f64; 3]> = centred.iter().map(|v| [v[0], v[2], v[1]]).collect();
    let side = contour_points(&side_view, bin_width * um);
    Ok(ShearPortrait {
        stress: experiment.stress,
        elongation_index: (result.el_mean, result.el_std),
        trace,
        window: (setup.t_start as f64 * rate, setup.t_max as f64 * rate),
        outline,
        ellipse: [
            e.centre[0],
            e.centre[1],
            e.semi_major,
            e.semi_minor,
            e.angle,
        ],
        side,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::MembraneParameters;
    use crate::run_shear;

    #[test]
    fn the_portrait_is_the_run_and_its_trace_ends_in_the_window() {
        let mut experiment = ShearExperiment::new(
            MembraneParameters {
                k_link: 100.0,
                k_bend: 200.0,
                ..Default::default()
            },
            5.0,
            2.91,
        );
        experiment.start_strain = 0.3;
        let plain = run_shear(&experiment).unwrap();
        let portrait = shear_portrait(&experiment, 40).unwrap();
        // The same run: the same elongation index, bit for bit.
        assert_eq!(portrait.elongation_index, (plain.el_mean, plain.el_std));
        assert!(portrait.trace.len() >= 20, "{}", portrait.trace.len());
        let (start, end) = portrait.window;
        assert!(start > 0.0 && end > start);
        let last = portrait.trace.last().unwrap();
        assert!(last.0 <= end + 1e-9 && last.0 > start, "{last:?}");
        // The outline is centred and about the cell's size (diameter 7.8 µm at rest).
        let width = portrait
            .outline
            .iter()
            .map(|p| p[0])
            .fold(f64::MIN, f64::max)
            - portrait
                .outline
                .iter()
                .map(|p| p[0])
                .fold(f64::MAX, f64::min);
        assert!((5.0..14.0).contains(&width), "{width}");
        let [_, _, a, b, _] = portrait.ellipse;
        assert!(a >= b && b > 0.0);
        // The ellipse of the last frame's outline gives that frame's elongation index.
        let el_last = (a - b) / (a + b);
        assert!((el_last - plain.frames.last().unwrap().elongation_index).abs() < 1e-9);
        assert!(!portrait.side.is_empty());
    }
}
