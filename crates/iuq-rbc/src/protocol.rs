//! The one-cell shear experiment and its measuring protocol.
//!
//! The box is HemoCell's `oneCellShear` as the study ran it: 40×40×20 nodes at dx = 0.5 µm,
//! flow along x, velocity walls on the node planes y = 0 and y = 39 (HemoCell's
//! `iniLatticeSquareCouette` of that time: periodic x and z, walls across y, gap 39 lattice
//! units), periodic in the 20-node vorticity direction z, and the cell centred at (19, 19, 9)
//! with its disk axis along z, i.e. the disk lies in the flow–gradient (shear) plane. The
//! elongation index is measured on the x–y projection, which is then the shear plane.
//!
//! This is also where HemoCell's own `oneCellShear` puts the cell (angles 90 0 0, checked
//! against HemoCell v2.1). The other placement one might read into the study's description —
//! the disk axis along the gradient, lying flat in the flow–vorticity plane — fails: the cell
//! flips over (Jeffery tumbling) within the measuring window, and the 10 frames at 0.64 Pa span
//! EL = 0.03…0.41 (std 0.145), whereas HemoCell reported a steady EL = 0.147 with a frame std of
//! ≈ 0.0035. With the axis along the vorticity the cell rolls and tank-treads steadily and the
//! same code gives EL ≈ 0.146 at 0.64 Pa and ≈ 0.36 / 0.49 at 2.91 / 6.19 Pa (HemoCell
//! 0.374 / 0.492), with no constant fitted.
//!
//! Internally the lattice has its walls across z ([`crate::lattice::ZBoundary`]), so the
//! simulation runs in the frame (flow, vorticity, gradient) = (x, y, z) on a 40×20×39 box; every
//! recorded shape is rotated back to HemoCell's frame (flow, gradient, vorticity) by
//! [`to_hemocell_frame`] before it is measured or written, so the shapes look exactly like
//! HemoCell's output. The walls move with `u_x = ±39·γ̇·dt/2`, `γ̇ = τ/(ρν)` for the
//! ektacytometer's shear stress τ; the fluid starts at rest. The cell shape is recorded 10 times,
//! evenly spaced in `[t_start, t_max]` with `t_start = int(7.5/(γ̇·dt))` and
//! `t_max = ceil(1.25·t_start)` (7.5 to 9.4 strain units); the quantity of interest is the mean
//! of the 10 elongation indices and its computational uncertainty their sample standard
//! deviation.
//!
//! Two protocols:
//! * [`Protocol::Reference`]: HemoCell's dt = 5e-8 s, so γ̇·dt = 6e-5 at 1.36 Pa and 155k steps;
//! * [`Protocol::Scaled`]: a fixed lattice shear rate (γ̇·dt = 3e-4 by default, cell Reynolds
//!   number γ̇R²/ν ≈ 0.08) with every force-like constant of the membrane, the 50 pN cap
//!   included, multiplied by `s = 3e-4/(γ̇·dt_ref)` so that the capillary number
//!   `τR/(kLink·kBT/p)`, kBend/kLink and Λ are HemoCell's: 31,250 steps at any stress. Only the
//!   (small) cell Reynolds number differs, and the fluid's time scale with it.

use std::time::Instant;

use crate::cell_in_flow::CellInFlow;
use crate::ellipse::elongation_index;
use crate::error::{RbcError, Result};
use crate::lattice::{Lattice, Precision, ZBoundary, on_pool_worker};
use crate::membrane_forces::{ForceCoefficients, ForceTerms, MembraneParameters, PastSingularity};
use crate::mesh::Mesh;
use crate::units::{CELL_RADIUS, LatticeUnits, shear_rate};

/// Nodes of the simulated box along flow x, vorticity y (periodic) and gradient z (between the
/// walls at z = 0 and z = 39): HemoCell's 40×40×20 box with its y and z axes exchanged.
pub const SHEAR_DOMAIN: [usize; 3] = [40, 20, 39];
/// Initial centre of the cell in the simulated frame, lattice units: HemoCell's (19, 19, 9)
/// after [`from_hemocell_frame`].
pub const CELL_CENTRE: [f64; 3] = [19.0, 11.0, 19.0];

/// Rotate a point of the simulated frame (flow, vorticity, gradient) into HemoCell's frame
/// (flow, gradient, vorticity): `(x, y, z) ↦ (x, z, ny − y)`, a proper rotation (so triangle
/// orientation and outward normals are kept) that maps the box onto HemoCell's.
pub fn to_hemocell_frame(p: [f64; 3]) -> [f64; 3] {
    [p[0], p[2], SHEAR_DOMAIN[1] as f64 - p[1]]
}

/// The inverse of [`to_hemocell_frame`].
pub fn from_hemocell_frame(p: [f64; 3]) -> [f64; 3] {
    [p[0], SHEAR_DOMAIN[1] as f64 - p[2], p[1]]
}
/// Lattice shear rate γ̇·dt of the scaled protocol.
pub const DEFAULT_LATTICE_SHEAR_RATE: f64 = 3e-4;
/// Strain at which measuring starts (`t_start = int(7.5/(γ̇·dt))`).
pub const START_STRAIN: f64 = 7.5;
/// `t_max = ceil(1.25·t_start)`.
pub const WINDOW_FACTOR: f64 = 1.25;
/// Shapes recorded in the measuring window.
pub const FRAMES: usize = 10;
/// The most shapes one run records.
pub const MAX_FRAMES: usize = 1000;
/// Width of the x bins of the contour, in metres (0.5 µm).
pub const CONTOUR_BIN_WIDTH: f64 = 0.5e-6;
/// Largest wall speed accepted, in lattice units (keeps the Mach number small).
pub const MAX_WALL_SPEED: f64 = 0.05;

/// How time is discretised.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case", tag = "kind")]
pub enum Protocol {
    /// HemoCell's time step dt = 5e-8 s.
    Reference,
    /// A fixed lattice shear rate with the membrane stiffness rescaled to the same capillary
    /// number.
    Scaled {
        /// γ̇·dt in lattice units.
        lattice_shear_rate: f64,
    },
}

impl Default for Protocol {
    /// [`Protocol::Scaled`] with γ̇·dt = 3e-4.
    fn default() -> Self {
        Protocol::Scaled {
            lattice_shear_rate: DEFAULT_LATTICE_SHEAR_RATE,
        }
    }
}

impl Protocol {
    /// The protocol's name: `reference` or `scaled`.
    pub fn name(&self) -> &'static str {
        match self {
            Protocol::Reference => "reference",
            Protocol::Scaled { .. } => "scaled",
        }
    }
}

impl std::str::FromStr for Protocol {
    type Err = RbcError;
    fn from_str(s: &str) -> Result<Self> {
        match s {
            "reference" => Ok(Protocol::Reference),
            "scaled" => Ok(Protocol::default()),
            other => Err(RbcError::InvalidData(format!(
                "unknown protocol `{other}` (expected `reference` or `scaled`)"
            ))),
        }
    }
}

/// One shear run: the cell's parameters, the stress and how to simulate.
#[derive(Debug, Clone, PartialEq)]
pub struct ShearExperiment {
    /// Membrane coefficients (kLink, kBend, kArea, kVolume).
    pub membrane: MembraneParameters,
    /// Interior/exterior viscosity ratio Λ.
    pub viscosity_ratio: f64,
    /// Shear stress of the ektacytometer in Pa.
    pub stress: f64,
    /// Time discretisation.
    pub protocol: Protocol,
    /// Strain at the start of the measuring window (7.5; shorter only for quick tests).
    pub start_strain: f64,
    /// The window ends at `t_max = ⌈window_factor·t_start⌉` (1.25, the study's window; a larger
    /// factor follows the cell further, e.g. to its periodic state at high stress).
    pub window_factor: f64,
    /// Number of recorded shapes (10).
    pub frames: usize,
    /// Storage precision of the fluid.
    pub precision: Precision,
    /// Spread the fluid update over rayon's threads (identical results either way).
    pub parallel: bool,
    /// Whether a strain past a force singularity carries on as HemoCell does (the default) or
    /// fails the run.
    pub past_singularity: PastSingularity,
    /// How the mesh starts in the disk plane.
    pub orientation: MeshOrientation,
}

/// How the membrane mesh starts in its disk plane (the shear plane). The subdivided icosahedron
/// is not round: which of its triangles lie at the tips of the elongating cell depends on this.
///
/// HemoCell's mesh generator rotates the mapped biconcave mesh once more after the map
/// (`helper/meshGeneratingFunctions.hh`), and the study's `RBC.pos` angles `90 0 0` rotate it
/// again; together the mesh is turned by 90° in the disk plane relative to the icosahedron's
/// own axes (HemoCell's five-neighbour rim vertices lie at (±0.526, ±0.851, 0)·R in its
/// flow–gradient plane, the unrotated mesh's at (±0.851, ±0.526, 0)·R). The two are the same
/// shape and give the same elongation wherever the membrane stays within its singularities; past
/// the area singularity (soft cells at 6.19–9.04 Pa) which triangles meet the load first decides
/// whether any crosses it (`data/hemocell_vs_native.md`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum MeshOrientation {
    /// The icosahedron's own axes (iuq's orientation until 2026-11-25; the studies made before
    /// used it, the shipped ones use [`MeshOrientation::Hemocell`]).
    #[default]
    Unrotated,
    /// HemoCell's: turned by 90° in the disk plane.
    Hemocell,
}

impl MeshOrientation {
    /// Both orientations.
    pub const ALL: [MeshOrientation; 2] = [Self::Unrotated, Self::Hemocell];

    /// The name used in study files and on the command line (`unrotated`, `hemocell`).
    pub fn name(&self) -> &'static str {
        match self {
            Self::Unrotated => "unrotated",
            Self::Hemocell => "hemocell",
        }
    }

    /// The orientation called `name` (see [`MeshOrientation::name`]).
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|o| o.name() == name)
    }

    /// Where vertex `v` of the unrotated mesh centred at `centre` starts, in HemoCell's frame
    /// (disk axis z): for `Hemocell`, turned by 90° about the disk axis through the centre.
    pub fn place(self, v: [f64; 3], centre: [f64; 3]) -> [f64; 3] {
        match self {
            Self::Unrotated => v,
            Self::Hemocell => [
                centre[0] - (v[1] - centre[1]),
                centre[1] + (v[0] - centre[0]),
                v[2],
            ],
        }
    }
}

impl ShearExperiment {
    /// The study's experiment at `stress` Pa for the given cell, scaled protocol.
    pub fn new(membrane: MembraneParameters, viscosity_ratio: f64, stress: f64) -> Self {
        Self {
            membrane,
            viscosity_ratio,
            stress,
            protocol: Protocol::default(),
            start_strain: START_STRAIN,
            window_factor: WINDOW_FACTOR,
            frames: FRAMES,
            precision: Precision::default(),
            parallel: true,
            past_singularity: PastSingularity::default(),
            orientation: MeshOrientation::default(),
        }
    }

    /// The same with another protocol.
    pub fn with_protocol(mut self, protocol: Protocol) -> Self {
        self.protocol = protocol;
        self
    }

    /// Check every input, naming the offending one.
    pub fn validate(&self) -> Result<()> {
        self.membrane.validate()?;
        if !(self.viscosity_ratio.is_finite() && self.viscosity_ratio > 0.0) {
            return Err(RbcError::invalid(
                "viscosityRatio",
                self.viscosity_ratio,
                "must be a positive finite number",
            ));
        }
        if !(self.stress.is_finite() && self.stress > 0.0) {
            return Err(RbcError::invalid(
                "stress",
                self.stress,
                "the shear stress must be a positive finite number of pascals",
            ));
        }
        if let Protocol::Scaled { lattice_shear_rate } = self.protocol {
            // Below 1e-5 a run takes millions of steps (the reference protocol's slowest, at
            // 0.64 Pa, is 2.8e-5); above 2e-3 the fluid is no longer at low Reynolds number.
            if !(1e-5..=2e-3).contains(&lattice_shear_rate) {
                return Err(RbcError::invalid(
                    "lattice_shear_rate",
                    lattice_shear_rate,
                    "must lie in [1e-5, 2e-3]",
                ));
            }
        }
        if !(self.start_strain.is_finite() && self.start_strain > 0.0) {
            return Err(RbcError::invalid(
                "start_strain",
                self.start_strain,
                "must be positive",
            ));
        }
        if !(self.window_factor.is_finite()
            && self.window_factor > 1.0
            && self.window_factor <= 100.0)
        {
            return Err(RbcError::invalid(
                "window_factor",
                self.window_factor,
                "the window ends at window_factor × its start: must lie in (1, 100]",
            ));
        }
        if !(2..=MAX_FRAMES).contains(&self.frames) {
            return Err(RbcError::invalid(
                "frames",
                self.frames as f64,
                format!(
                    "from 2 (a standard deviation needs two) to {MAX_FRAMES} frames (each keeps a shape)"
                ),
            ));
        }
        let setup = self.setup();
        let wall = 0.5 * SHEAR_DOMAIN[2] as f64 * setup.lattice_shear_rate;
        if wall > MAX_WALL_SPEED {
            return Err(RbcError::invalid(
                "stress",
                self.stress,
                format!(
                    "the wall speed {wall:.3} (lattice units) of the {} protocol exceeds {MAX_WALL_SPEED}; use the scaled protocol",
                    self.protocol.name()
                ),
            ));
        }
        Ok(())
    }

    /// The derived lattice quantities of this run.
    pub fn setup(&self) -> ShearSetup {
        let units = LatticeUnits::reference();
        let rate = shear_rate(self.stress);
        let reference_rate = rate * units.dt;
        let (lattice_shear_rate, force_scale) = match self.protocol {
            Protocol::Reference => (reference_rate, 1.0),
            Protocol::Scaled { lattice_shear_rate } => {
                (lattice_shear_rate, lattice_shear_rate / reference_rate)
            }
        };
        let coefficients =
            ForceCoefficients::hemocell(&self.membrane, &units, 1280).scaled(force_scale);
        let t_start = (self.start_strain / lattice_shear_rate) as u64;
        let t_max = (self.window_factor * t_start as f64).ceil() as u64;
        let n = self.frames.max(2) as u64;
        let frames = (0..n)
            .map(|i| t_start + ((i * (t_max - t_start)) as f64 / (n - 1) as f64).round() as u64)
            .collect();
        let radius = CELL_RADIUS / units.dx;
        ShearSetup {
            shear_rate: rate,
            lattice_shear_rate,
            force_scale,
            coefficients,
            relaxation_time: units.relaxation_time(),
            t_start,
            t_max,
            frames,
            reynolds: lattice_shear_rate * radius * radius / units.viscosity_lu(),
            bin_width: CONTOUR_BIN_WIDTH / units.dx,
        }
    }
}

/// Derived quantities of one shear run.
#[derive(Debug, Clone, PartialEq)]
pub struct ShearSetup {
    /// Physical shear rate γ̇ = τ/(ρν) in 1/s.
    pub shear_rate: f64,
    /// γ̇·dt in lattice units.
    pub lattice_shear_rate: f64,
    /// Factor applied to every force-like constant (1 for the reference protocol).
    pub force_scale: f64,
    /// Force coefficients in lattice units, scaled.
    pub coefficients: ForceCoefficients,
    /// Exterior relaxation time τ.
    pub relaxation_time: f64,
    /// First measuring step.
    pub t_start: u64,
    /// Last step.
    pub t_max: u64,
    /// Steps at which the shape is recorded.
    pub frames: Vec<u64>,
    /// Cell Reynolds number γ̇R²/ν.
    pub reynolds: f64,
    /// Contour bin width in lattice units.
    pub bin_width: f64,
}

/// A recorded shape.
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    /// Time step.
    pub step: u64,
    /// Vertex positions in HemoCell's frame (x flow, y gradient, z vorticity; lattice units).
    pub vertices: Vec<[f64; 3]>,
    /// Elongation index of this shape.
    pub elongation_index: f64,
}

/// The outcome of one shear run.
#[derive(Debug, Clone, PartialEq)]
pub struct ShearResult {
    /// Mean of the frames' elongation indices.
    pub el_mean: f64,
    /// Their sample standard deviation.
    pub el_std: f64,
    /// The recorded shapes.
    pub frames: Vec<Frame>,
    /// The mesh's triangles (to write the shapes).
    pub triangles: Vec<[usize; 3]>,
    /// Steps simulated.
    pub steps: u64,
    /// Wall-clock seconds.
    pub seconds: f64,
    /// Million lattice node updates per second over the whole run (membrane included).
    pub mlups: f64,
    /// The derived quantities.
    pub setup: ShearSetup,
}

impl ShearResult {
    /// The frames' elongation indices.
    pub fn el_frames(&self) -> Vec<f64> {
        self.frames.iter().map(|f| f.elongation_index).collect()
    }

    /// The elongation's drift over the measuring window: the least-squares slope of the frames'
    /// elongation indices against their steps, times the window's length in steps. Near zero
    /// when the cell has reached a steady shape; of the order of the frames' standard deviation
    /// (or larger) when the shape still moves through the window.
    pub fn el_drift(&self) -> f64 {
        let points: Vec<(f64, f64)> = self
            .frames
            .iter()
            .map(|f| (f.step as f64, f.elongation_index))
            .collect();
        least_squares_slope(&points) * (self.setup.t_max - self.setup.t_start) as f64
    }
}

/// Slope of the least-squares line through `points` (0 with fewer than two distinct abscissae).
pub fn least_squares_slope(points: &[(f64, f64)]) -> f64 {
    let n = points.len() as f64;
    if points.len() < 2 {
        return 0.0;
    }
    let mx = points.iter().map(|p| p.0).sum::<f64>() / n;
    let my = points.iter().map(|p| p.1).sum::<f64>() / n;
    let sxx: f64 = points.iter().map(|p| (p.0 - mx).powi(2)).sum();
    let sxy: f64 = points.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    if sxx > 0.0 { sxy / sxx } else { 0.0 }
}

/// Mean and sample standard deviation (n − 1).
pub fn mean_and_sample_std(values: &[f64]) -> (f64, f64) {
    let n = values.len() as f64;
    let mean = values.iter().sum::<f64>() / n;
    let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0).max(1.0);
    (mean, var.sqrt())
}

/// Build the shear box with the cell at rest in it.
pub fn shear_cell(experiment: &ShearExperiment, setup: &ShearSetup) -> Result<CellInFlow> {
    let [nx, ny, nz] = SHEAR_DOMAIN;
    let wall = 0.5 * nz as f64 * setup.lattice_shear_rate;
    let walls = ZBoundary::Walls {
        bottom: [-wall, 0.0, 0.0],
        top: [wall, 0.0, 0.0],
    };
    let mut lattice = Lattice::new(
        nx,
        ny,
        nz,
        walls,
        setup.relaxation_time,
        experiment.precision,
    );
    lattice.set_parallel(experiment.parallel);
    // HemoCell's cell at (19, 19, 9) with its axis along HemoCell's z (the vorticity).
    let centre = to_hemocell_frame(CELL_CENTRE);
    let mut mesh = Mesh::red_blood_cell_lu(LatticeUnits::reference().dx, centre);
    for v in &mut mesh.vertices {
        *v = from_hemocell_frame(experiment.orientation.place(*v, centre));
    }
    let mut cell = CellInFlow::new(
        lattice,
        mesh,
        setup.coefficients,
        Some(experiment.viscosity_ratio),
    )?;
    cell.set_force_terms(ForceTerms {
        past_singularity: experiment.past_singularity,
        ..ForceTerms::default()
    });
    Ok(cell)
}

/// Run the shear experiment and measure the elongation index.
///
/// Fails with the reason when the mesh breaks, a value becomes non-finite, the cell leaves the
/// channel or a recorded contour admits no ellipse.
pub fn run_shear(experiment: &ShearExperiment) -> Result<ShearResult> {
    on_pool_worker(|| run_shear_on_worker(experiment, None))
}

/// What [`run_shear_observed`] hands each shape to: the step and the vertices (HemoCell's
/// frame).
pub(crate) type ShapeObserver<'a> = &'a mut (dyn FnMut(u64, &[[f64; 3]]) + Send);

/// [`run_shear`], also handing the shape (HemoCell's frame) to `observe` every `every` steps
/// (`crate::shear_trace` records the elongation over the whole run this way). The run and its
/// result are those of [`run_shear`]: the observer only reads the positions.
pub(crate) fn run_shear_observed(
    experiment: &ShearExperiment,
    every: u64,
    observe: ShapeObserver<'_>,
) -> Result<ShearResult> {
    on_pool_worker(|| run_shear_on_worker(experiment, Some((every.max(1), observe))))
}

fn run_shear_on_worker(
    experiment: &ShearExperiment,
    mut observer: Option<(u64, ShapeObserver<'_>)>,
) -> Result<ShearResult> {
    experiment.validate()?;
    let setup = experiment.setup();
    let started = Instant::now();
    let mut cell = shear_cell(experiment, &setup)?;
    let mut frames = Vec::with_capacity(setup.frames.len());
    let mut next = 0;
    while cell.steps() < setup.t_max {
        cell.step()?;
        if let Some((every, observe)) = observer.as_mut()
            && cell.steps() % *every == 0
        {
            let vertices: Vec<[f64; 3]> = cell
                .positions()
                .iter()
                .map(|&p| to_hemocell_frame(p))
                .collect();
            observe(cell.steps(), &vertices);
        }
        while next < setup.frames.len() && setup.frames[next] == cell.steps() {
            let vertices: Vec<[f64; 3]> = cell
                .positions()
                .iter()
                .map(|&p| to_hemocell_frame(p))
                .collect();
            let el = elongation_index(&vertices, setup.bin_width).map_err(|e| match e {
                RbcError::NoEllipse(reason) => {
                    RbcError::NoEllipse(format!("at step {}: {reason}", cell.steps()))
                }
                other => other,
            })?;
            frames.push(Frame {
                step: cell.steps(),
                vertices,
                elongation_index: el,
            });
            next += 1;
        }
    }
    let seconds = started.elapsed().as_secs_f64();
    let el: Vec<f64> = frames.iter().map(|f| f.elongation_index).collect();
    let (el_mean, el_std) = mean_and_sample_std(&el);
    let nodes = SHEAR_DOMAIN.iter().product::<usize>() as f64;
    Ok(ShearResult {
        el_mean,
        el_std,
        frames,
        triangles: cell.mesh().triangles.clone(),
        steps: cell.steps(),
        seconds,
        mlups: cell.steps() as f64 * nodes / seconds.max(1e-12) / 1e6,
        setup,
    })
}

#[cfg(test)]
mod tests {

    #[test]
    fn hemocell_orientation_puts_the_five_neighbour_rim_vertices_where_hemocell_has_them() {
        // HemoCell's first frame: the rim vertices with five neighbours at (±0.526, ±0.851, 0)·R
        // in its flow–gradient plane; the unrotated mesh has them at (±0.851, ±0.526, 0)·R.
        let centre = [0.0; 3];
        let mesh = Mesh::red_blood_cell(1.0, centre);
        for (orientation, cos) in [
            (MeshOrientation::Unrotated, 0.851),
            (MeshOrientation::Hemocell, 0.526),
        ] {
            let rim: Vec<[f64; 3]> = (0..mesh.vertices.len())
                .filter(|&i| mesh.ring(i).len() == 5 && mesh.vertices[i][2].abs() < 1e-9)
                .map(|i| orientation.place(mesh.vertices[i], centre))
                .collect();
            assert_eq!(rim.len(), 4, "{orientation:?}");
            for v in rim {
                let r = v[0].hypot(v[1]);
                assert!(
                    (v[0].abs() / r - cos).abs() < 1e-3,
                    "{orientation:?}: {v:?}"
                );
            }
        }
        assert_eq!(
            MeshOrientation::from_name("hemocell"),
            Some(MeshOrientation::Hemocell)
        );
        assert_eq!(MeshOrientation::default(), MeshOrientation::Unrotated);
    }

    use super::*;

    #[test]
    fn step_counts_match_the_spec() {
        let cell = MembraneParameters::default();
        for (stress, steps) in [
            (0.30, 705_000.0),
            (1.36, 155_000.0),
            (2.91, 73_000.0),
            (9.04, 23_000.0),
        ] {
            let s = ShearExperiment::new(cell, 5.0, stress)
                .with_protocol(Protocol::Reference)
                .setup();
            assert!(
                ((s.t_max as f64 - steps) / steps).abs() < 0.02,
                "{stress}: {}",
                s.t_max
            );
            assert_eq!(s.frames.len(), 10);
            assert_eq!((s.frames[0], s.frames[9]), (s.t_start, s.t_max));
            assert_eq!(s.force_scale, 1.0);
        }
        let s = ShearExperiment::new(cell, 5.0, 1.36).setup();
        assert_eq!((s.t_start, s.t_max), (25_000, 31_250));
        // Same capillary number: force scale × reference lattice shear rate = 3e-4.
        let reference_rate = shear_rate(1.36) * 5e-8;
        assert!((s.force_scale * reference_rate - 3e-4).abs() < 1e-15);
        assert!(s.reynolds < 0.1);
    }

    #[test]
    fn bad_inputs_are_named() {
        let cell = MembraneParameters::default();
        let e = ShearExperiment::new(cell, 5.0, -1.0)
            .validate()
            .unwrap_err();
        assert!(
            e.is_input_error() && e.to_string().contains("stress"),
            "{e}"
        );
        let e = ShearExperiment::new(cell, f64::NAN, 1.0)
            .validate()
            .unwrap_err();
        assert!(e.to_string().contains("viscosityRatio"), "{e}");
        let bad = MembraneParameters {
            k_link: 0.0,
            ..cell
        };
        let e = ShearExperiment::new(bad, 5.0, 1.0).validate().unwrap_err();
        assert!(e.to_string().contains("kLink"), "{e}");
        let e = ShearExperiment::new(cell, 5.0, 500.0)
            .with_protocol(Protocol::Reference)
            .validate()
            .unwrap_err();
        assert!(e.to_string().contains("wall speed"), "{e}");
        assert!("fast".parse::<Protocol>().is_err());
    }

    #[test]
    fn the_cell_starts_with_its_disk_in_the_shear_plane() {
        let e = ShearExperiment::new(MembraneParameters::default(), 5.0, 1.0);
        let cell = shear_cell(&e, &e.setup()).unwrap();
        let x: Vec<[f64; 3]> = cell.positions().to_vec();
        let extent = |v: &[[f64; 3]], k: usize| {
            let lo = v.iter().map(|p| p[k]).fold(f64::MAX, f64::min);
            let hi = v.iter().map(|p| p[k]).fold(f64::MIN, f64::max);
            hi - lo
        };
        // Simulated frame: the thin axis is the vorticity y.
        assert!(extent(&x, 1) < 5.0 && extent(&x, 0) > 15.0 && extent(&x, 2) > 15.0);
        let h: Vec<[f64; 3]> = x.iter().map(|&p| to_hemocell_frame(p)).collect();
        let n = h.len() as f64;
        let centre: Vec<f64> = (0..3)
            .map(|k| h.iter().map(|p| p[k]).sum::<f64>() / n)
            .collect();
        for (c, want) in centre.iter().zip([19.0, 19.0, 9.0]) {
            assert!((c - want).abs() < 1e-9, "{centre:?}");
        }
        // HemoCell's frame: the face of the disk is the measured x–y projection.
        assert!(extent(&h, 2) < 5.0);
        let el = elongation_index(&h, e.setup().bin_width).unwrap();
        assert!(el < 0.01, "{el}");
        // A proper rotation keeps the enclosed volume positive.
        let v = crate::mesh::volume(&cell.mesh().triangles, &h);
        assert!((v - crate::mesh::volume(&cell.mesh().triangles, &x)).abs() < 1e-9 && v > 0.0);
        for p in &x {
            let back = from_hemocell_frame(to_hemocell_frame(*p));
            assert!((0..3).all(|k| (back[k] - p[k]).abs() < 1e-12));
        }
    }

    #[test]
    fn sample_std_uses_n_minus_one() {
        let (m, s) = mean_and_sample_std(&[1.0, 2.0, 3.0, 4.0]);
        assert_eq!(m, 2.5);
        assert!((s - (5.0f64 / 3.0).sqrt()).abs() < 1e-15);
    }

    #[test]
    fn the_drift_is_the_least_squares_change_over_the_window() {
        // Frames on the line EL = 0.5 − 0.02·(step − t_start)/(t_max − t_start): the drift is
        // the line's change over the window, −0.02.
        assert!((least_squares_slope(&[(0.0, 1.0), (1.0, 3.0), (2.0, 5.0)]) - 2.0).abs() < 1e-15);
        assert_eq!(least_squares_slope(&[(1.0, 1.0)]), 0.0);
        assert_eq!(least_squares_slope(&[(1.0, 1.0), (1.0, 2.0)]), 0.0);
        let experiment = ShearExperiment::new(MembraneParameters::default(), 5.0, 9.04);
        let setup = experiment.setup();
        let span = (setup.t_max - setup.t_start) as f64;
        let frames = setup
            .frames
            .iter()
            .map(|&step| Frame {
                step,
                vertices: Vec::new(),
                elongation_index: 0.5 - 0.02 * (step - setup.t_start) as f64 / span,
            })
            .collect();
        let result = ShearResult {
            el_mean: 0.49,
            el_std: 0.0,
            frames,
            triangles: Vec::new(),
            steps: setup.t_max,
            seconds: 0.0,
            mlups: 0.0,
            setup,
        };
        assert!(
            (result.el_drift() + 0.02).abs() < 1e-12,
            "{}",
            result.el_drift()
        );
    }

    #[test]
    fn a_longer_window_keeps_its_start_and_spreads_the_frames_to_its_end() {
        let study = ShearExperiment::new(MembraneParameters::default(), 5.0, 9.04);
        let long = ShearExperiment {
            window_factor: 4.0,
            frames: 31,
            ..study.clone()
        };
        let (a, b) = (study.setup(), long.setup());
        assert_eq!(a.t_start, b.t_start);
        assert_eq!(b.t_max, (4.0 * b.t_start as f64).ceil() as u64);
        assert_eq!(b.frames.len(), 31);
        assert_eq!((b.frames[0], b.frames[30]), (b.t_start, b.t_max));
        for bad in [1.0, 0.5, f64::NAN, 101.0] {
            let e = ShearExperiment {
                window_factor: bad,
                ..study.clone()
            };
            let err = e.validate().unwrap_err().to_string();
            assert!(err.contains("window_factor"), "{err}");
        }
    }
}
