//! `iuq rbc …`: the native single red-blood-cell simulator (HemoCell-compatible shear
//! experiment), its validation and its benchmark. The `[model] kind = "rbc-shear"` section of
//! study files is read by [`iuq_study::rbc_section`].

use std::path::PathBuf;

use anyhow::{Result, anyhow};
use clap::{Args, Subcommand, ValueEnum};
use serde_json::json;

use iuq_rbc::benchmark::{LatticeBenchmark, benchmark_lattice, memory_copy_bandwidth};
use iuq_rbc::lattice::Precision;
use iuq_rbc::protocol::{
    DEFAULT_LATTICE_SHEAR_RATE, FRAMES, Protocol, SHEAR_DOMAIN, START_STRAIN, ShearExperiment,
    WINDOW_FACTOR, run_shear,
};
use iuq_rbc::shape_output::ShapeFormat;
use iuq_rbc::stretching::{OPTICAL_TWEEZERS, StretchExperiment, run_stretch};
use iuq_rbc::validation::{validate_shear, validate_stretch};
use iuq_rbc::{MembraneParameters, MeshOrientation, PastSingularity, RbcError};

use crate::input_error::input_error;
use crate::report_output::{emit, short};

/// The verbs of `iuq rbc`.
#[derive(Debug, Subcommand)]
pub enum RbcCommand {
    /// One shear run: the elongation index of a cell at one shear stress.
    Shear(ShearArgs),
    /// The optical-tweezers stretching check: the axial diameter under a pulling force.
    Stretch(StretchArgs),
    /// Compare with HemoCell's elongation indices and the optical-tweezers data (minutes to
    /// hours of computing).
    Validate(ValidateArgs),
    /// Lattice update rate (MLUPS) and the fraction of the memory copy bandwidth it reaches.
    Bench(BenchArgs),
    /// The elongation index of membrane frames from files (vertex CSV, VTK or PLY), e.g.
    /// HemoCell's output decoded by `examples/hemocell/decode-el.py`.
    Elongation(super::rbc_elongation::ElongationArgs),
}

/// Time discretisation of a shear run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ProtocolArg {
    /// HemoCell's time step (5e-8 s): 155k steps at 1.36 Pa.
    Reference,
    /// Fixed lattice shear rate, membrane forces rescaled to the same capillary number:
    /// 31,250 steps at any stress.
    Scaled,
}

/// File format of `--shape-out`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ShapeFormatArg {
    /// Legacy VTK polydata (ParaView).
    Vtk,
    /// ASCII PLY (MeshLab, Blender).
    Ply,
}

/// Storage precision of the fluid populations.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum PrecisionArg {
    /// 4-byte deviations from the rest weights (default; arithmetic in double).
    Single,
    /// 8-byte populations.
    Double,
}

impl From<PrecisionArg> for Precision {
    fn from(p: PrecisionArg) -> Self {
        match p {
            PrecisionArg::Single => Precision::Single,
            PrecisionArg::Double => Precision::Double,
        }
    }
}

/// What a strain past a singularity of the membrane's force laws means.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum PastSingularityArg {
    /// The run fails (the mesh is taken as broken).
    Fail,
    /// Carry on with the absolute-value force laws and the 50 pN cap, as HemoCell does.
    CarryOn,
}

impl From<PastSingularityArg> for PastSingularity {
    fn from(p: PastSingularityArg) -> Self {
        match p {
            PastSingularityArg::Fail => PastSingularity::Fail,
            PastSingularityArg::CarryOn => PastSingularity::CarryOn,
        }
    }
}

/// How the mesh starts in the disk plane.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum OrientationArg {
    /// The icosahedron's own axes (iuq's orientation until 2026-11-25; the default, so that stores
    /// made before keep their meaning).
    Unrotated,
    /// Turned 90° in the disk plane, as HemoCell's mesh generator and RBC.pos leave it.
    Hemocell,
}

impl From<OrientationArg> for MeshOrientation {
    fn from(o: OrientationArg) -> Self {
        match o {
            OrientationArg::Unrotated => MeshOrientation::Unrotated,
            OrientationArg::Hemocell => MeshOrientation::Hemocell,
        }
    }
}

/// Arguments of `iuq rbc shear`.
#[derive(Debug, Args)]
pub struct ShearArgs {
    /// Link (spectrin) coefficient kLink, in kBT.
    #[arg(long, default_value_t = 15.0, allow_negative_numbers = true)]
    pub klink: f64,
    /// Bending coefficient kBend, in kBT.
    #[arg(long, default_value_t = 80.0, allow_negative_numbers = true)]
    pub kbend: f64,
    /// Interior/exterior viscosity ratio Λ.
    #[arg(long, default_value_t = 5.0, allow_negative_numbers = true)]
    pub viscosity_ratio: f64,
    /// Local area coefficient kArea, in kBT.
    #[arg(long, default_value_t = 5.0, allow_negative_numbers = true)]
    pub karea: f64,
    /// Volume coefficient kVolume, in kBT.
    #[arg(long, default_value_t = 20.0, allow_negative_numbers = true)]
    pub kvolume: f64,
    /// Shear stress of the ektacytometer, in Pa.
    #[arg(long, allow_negative_numbers = true)]
    pub stress: f64,
    /// Time discretisation.
    #[arg(long, value_enum, default_value_t = ProtocolArg::Scaled)]
    pub protocol: ProtocolArg,
    /// Lattice shear rate γ̇·dt of the scaled protocol.
    #[arg(long, default_value_t = DEFAULT_LATTICE_SHEAR_RATE, allow_negative_numbers = true)]
    pub lattice_shear_rate: f64,
    /// Strain at which the measuring window starts (7.5 in the study's protocol; smaller only for
    /// quick checks).
    #[arg(long, default_value_t = START_STRAIN, allow_negative_numbers = true)]
    pub start_strain: f64,
    /// The measuring window ends at this factor × its start step (1.25, the study's window; e.g.
    /// 4 follows the cell from strain 7.5 to 30).
    #[arg(long, default_value_t = WINDOW_FACTOR, allow_negative_numbers = true)]
    pub window_factor: f64,
    /// Shapes recorded, evenly spaced over the window, both ends included.
    #[arg(long, default_value_t = FRAMES)]
    pub frames: usize,
    /// Storage precision of the fluid.
    #[arg(long, value_enum, default_value_t = PrecisionArg::Single)]
    pub precision: PrecisionArg,
    /// A strain past a singularity of the membrane's force laws: `carry-on` (as HemoCell does:
    /// absolute-value denominators, forces capped at 50 pN) or `fail` (a broken mesh).
    #[arg(long, value_enum, default_value_t = PastSingularityArg::CarryOn)]
    pub past_singularity: PastSingularityArg,
    /// How the mesh starts in the disk plane: `unrotated` (the icosahedron's axes, iuq's
    /// orientation so far) or `hemocell` (turned 90° as HemoCell's generator and RBC.pos leave
    /// it; agrees with HemoCell v2.1 at 12 of 12 compared points, see data/hemocell_vs_native.md).
    #[arg(long, value_enum, default_value_t = OrientationArg::Unrotated)]
    pub initial_orientation: OrientationArg,
    /// Write the membrane at each measuring frame into this directory.
    #[arg(long)]
    pub shape_out: Option<PathBuf>,
    /// Format of the shapes written by --shape-out.
    #[arg(long, value_enum, default_value_t = ShapeFormatArg::Vtk)]
    pub shape_format: ShapeFormatArg,
}

/// Map a simulator error to the command line: bad values name the flag (exit code 2), failed
/// runs are failures of the work (exit code 1).
fn cli_error(e: RbcError) -> anyhow::Error {
    match &e {
        RbcError::InvalidParameter {
            name,
            value,
            reason,
        } => {
            let flag = match name.as_str() {
                "kLink" => "--klink",
                "kBend" => "--kbend",
                "kArea" => "--karea",
                "kVolume" => "--kvolume",
                "viscosityRatio" => "--viscosity-ratio",
                "stress" => "--stress",
                "lattice_shear_rate" => "--lattice-shear-rate",
                "start_strain" => "--start-strain",
                "window_factor" => "--window-factor",
                "frames" => "--frames",
                "force" => "--force",
                "force_scale" => "--force-scale",
                other => other,
            };
            input_error(format!("{flag}: invalid value {value}: {reason}"))
        }
        RbcError::InvalidData(message) => input_error(message.clone()),
        _ => anyhow!(e),
    }
}

/// Run `iuq rbc …`.
pub fn run(command: &RbcCommand, json: bool) -> Result<()> {
    match command {
        RbcCommand::Shear(args) => shear(args, json),
        RbcCommand::Stretch(args) => stretch(args, json),
        RbcCommand::Validate(args) => validate(args, json),
        RbcCommand::Bench(args) => bench(args, json),
        RbcCommand::Elongation(args) => super::rbc_elongation::run(args, json),
    }
}

fn shear(args: &ShearArgs, json: bool) -> Result<()> {
    let membrane = MembraneParameters {
        k_link: args.klink,
        k_bend: args.kbend,
        k_area: args.karea,
        k_volume: args.kvolume,
    };
    let protocol = match args.protocol {
        ProtocolArg::Reference => Protocol::Reference,
        ProtocolArg::Scaled => Protocol::Scaled {
            lattice_shear_rate: args.lattice_shear_rate,
        },
    };
    let mut experiment =
        ShearExperiment::new(membrane, args.viscosity_ratio, args.stress).with_protocol(protocol);
    experiment.start_strain = args.start_strain;
    experiment.window_factor = args.window_factor;
    experiment.frames = args.frames;
    experiment.precision = args.precision.into();
    experiment.past_singularity = args.past_singularity.into();
    experiment.orientation = args.initial_orientation.into();
    experiment.validate().map_err(cli_error)?;
    if let Some(dir) = &args.shape_out {
        std::fs::create_dir_all(dir).map_err(|e| {
            input_error(format!("--shape-out: cannot create {}: {e}", dir.display()))
        })?;
    }
    let result = run_shear(&experiment).map_err(cli_error)?;
    let mut shapes = Vec::new();
    if let Some(dir) = &args.shape_out {
        let format = match args.shape_format {
            ShapeFormatArg::Vtk => ShapeFormat::Vtk,
            ShapeFormatArg::Ply => ShapeFormat::Ply,
        };
        for (i, frame) in result.frames.iter().enumerate() {
            let path = dir.join(format!(
                "frame_{i:02}_step_{:07}.{}",
                frame.step,
                format.extension()
            ));
            let title = format!(
                "iuq rbc shear: stress {} Pa, step {}, EL {:.4} (lattice units)",
                args.stress, frame.step, frame.elongation_index
            );
            let text = format.render(&result.triangles, &frame.vertices, &title);
            std::fs::write(&path, text)
                .map_err(|e| anyhow!("cannot write {}: {e}", path.display()))?;
            shapes.push(path.display().to_string());
        }
    }
    let el_frames = result.el_frames();
    let el_drift = result.el_drift();
    let value = json!({
        "el_mean": result.el_mean,
        "el_std": result.el_std,
        // The same as one value with its computational std, the form campaign decoders read.
        "el": { "value": result.el_mean, "std": result.el_std },
        "el_frames": el_frames,
        // The least-squares change of EL over the window: how far the shape still moves.
        "el_drift": el_drift,
        "start_strain": result.setup.t_start as f64 * result.setup.lattice_shear_rate,
        "end_strain": result.setup.t_max as f64 * result.setup.lattice_shear_rate,
        "past_singularity": experiment.past_singularity.name(),
        "initial_orientation": experiment.orientation.name(),
        "steps": result.steps,
        "seconds": result.seconds,
        "mlups": result.mlups,
        "frame_steps": result.frames.iter().map(|f| f.step).collect::<Vec<_>>(),
        "protocol": protocol.name(),
        "stress": args.stress,
        "parameters": {
            "kLink": args.klink, "kBend": args.kbend, "viscosityRatio": args.viscosity_ratio,
            "kArea": args.karea, "kVolume": args.kvolume,
        },
        "lattice_shear_rate": result.setup.lattice_shear_rate,
        "force_scale": result.setup.force_scale,
        "reynolds": result.setup.reynolds,
        "shapes": shapes,
    });
    emit(json, &value, || {
        let frames: Vec<String> = el_frames.iter().map(|v| format!("{v:.4}")).collect();
        let mut text = format!(
            "EL = {} ± {} at {} Pa ({} protocol)\nframes: {} (drift over the window {})\n{} steps in {} s ({} MLUPS)",
            short(result.el_mean),
            short(result.el_std),
            args.stress,
            protocol.name(),
            frames.join(" "),
            short(el_drift),
            result.steps,
            short(result.seconds),
            short(result.mlups)
        );
        if !shapes.is_empty() {
            text.push_str(&format!("\nshapes: {}", shapes.join(", ")));
        }
        text
    });
    Ok(())
}

/// Arguments of `iuq rbc stretch`.
#[derive(Debug, Args)]
pub struct StretchArgs {
    /// Pulling force in pN (repeat for several; default: 1.8, 15, 35 and 62).
    #[arg(long = "force", allow_negative_numbers = true)]
    pub forces: Vec<f64>,
    /// Link coefficient kLink, in kBT.
    #[arg(long, default_value_t = 15.0, allow_negative_numbers = true)]
    pub klink: f64,
    /// Bending coefficient kBend, in kBT.
    #[arg(long, default_value_t = 80.0, allow_negative_numbers = true)]
    pub kbend: f64,
    /// Factor on every force (shortens the relaxation; the equilibrium does not depend on it).
    #[arg(long, default_value_t = 10.0, allow_negative_numbers = true)]
    pub force_scale: f64,
}

fn stretch(args: &StretchArgs, json: bool) -> Result<()> {
    let forces = if args.forces.is_empty() {
        OPTICAL_TWEEZERS.iter().map(|m| m.force_pn).collect()
    } else {
        args.forces.clone()
    };
    let experiments: Vec<StretchExperiment> = forces
        .iter()
        .map(|&f| {
            let mut e = StretchExperiment::new(f);
            e.membrane.k_link = args.klink;
            e.membrane.k_bend = args.kbend;
            e.force_scale = args.force_scale;
            e
        })
        .collect();
    for e in &experiments {
        e.membrane.validate().map_err(cli_error)?;
        if !(e.force_pn.is_finite() && e.force_pn >= 0.0) {
            return Err(input_error(format!(
                "--force: invalid value {}: must be a non-negative number of pN",
                e.force_pn
            )));
        }
        if !(e.force_scale.is_finite() && e.force_scale > 0.0) {
            return Err(input_error(format!(
                "--force-scale: invalid value {}: must be positive",
                e.force_scale
            )));
        }
    }
    let mut rows = Vec::new();
    for e in &experiments {
        let r = run_stretch(e).map_err(cli_error)?;
        rows.push(r);
    }
    let value = json!({ "klink": args.klink, "kbend": args.kbend, "results": rows });
    emit(json, &value, || {
        let mut text = format!(
            "{:>10} {:>12} {:>16} {:>10}\n",
            "force pN", "axial µm", "transverse µm", "steps"
        );
        for r in &rows {
            text.push_str(&format!(
                "{:>10} {:>12.3} {:>16.3} {:>10}{}\n",
                r.force_pn,
                r.axial_um,
                r.transverse_um,
                r.steps,
                if r.converged { "" } else { " (not converged)" }
            ));
        }
        text
    });
    Ok(())
}

/// Which shear validation tables to run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ValidateProtocol {
    /// The scaled protocol only (7 runs of 31,250 steps).
    Scaled,
    /// The reference protocol only (7 runs of 34k–330k steps: 0.64–6.19 Pa).
    Reference,
    /// Both.
    Both,
    /// No shear runs (with --stretch: only the stretching check).
    None,
}

/// Arguments of `iuq rbc validate`.
#[derive(Debug, Args)]
pub struct ValidateArgs {
    /// Shear tables to run (kLink = 36.7, kBend = 367, Λ = 5.9 at the seven stresses of
    /// HemoCell's validation).
    #[arg(long, value_enum, default_value_t = ValidateProtocol::Scaled)]
    pub protocol: ValidateProtocol,
    /// Also run the optical-tweezers stretching check (kLink = 15, kBend = 80).
    #[arg(long)]
    pub stretch: bool,
    /// A strain past a force singularity: `carry-on` (as HemoCell) or `fail` (a broken mesh).
    #[arg(long, value_enum, default_value_t = PastSingularityArg::CarryOn)]
    pub past_singularity: PastSingularityArg,
}

fn validate(args: &ValidateArgs, json: bool) -> Result<()> {
    let protocols: Vec<Protocol> = match args.protocol {
        ValidateProtocol::Scaled => vec![Protocol::default()],
        ValidateProtocol::Reference => vec![Protocol::Reference],
        ValidateProtocol::Both => vec![Protocol::default(), Protocol::Reference],
        ValidateProtocol::None => vec![],
    };
    let past_singularity = args.past_singularity.into();
    let shear_rows: Vec<_> = protocols
        .into_iter()
        .flat_map(|p| validate_shear(p, past_singularity))
        .collect();
    let stretch_rows = if args.stretch {
        validate_stretch()
    } else {
        Vec::new()
    };
    let value = json!({ "shear": shear_rows, "stretch": stretch_rows });
    emit(json, &value, || {
        let mut text = String::new();
        let percent = |d: Option<f64>| d.map_or("-".into(), |v| format!("{:+.1}%", 100.0 * v));
        if !shear_rows.is_empty() {
            text.push_str(&format!(
                "{:<10} {:>8} {:>9} {:>9} {:>8} {:>8}  {}\n",
                "protocol", "τ Pa", "HemoCell", "EL", "± std", "diff", "note"
            ));
            for r in &shear_rows {
                text.push_str(&format!(
                    "{:<10} {:>8} {:>9.3} {:>9} {:>8} {:>8}  {}\n",
                    r.protocol,
                    r.stress,
                    r.hemocell,
                    r.el_mean.map_or("-".into(), |v| format!("{v:.4}")),
                    r.el_std.map_or("-".into(), |v| format!("{v:.4}")),
                    percent(r.relative_difference),
                    r.failure.clone().unwrap_or_default()
                ));
            }
        }
        if !stretch_rows.is_empty() {
            text.push_str(&format!(
                "{:>10} {:>10} {:>10} {:>8} {:>10} {:>14} {:>8}\n",
                "force pN", "measured", "axial µm", "diff", "measured", "transverse µm", "diff"
            ));
            for r in &stretch_rows {
                text.push_str(&format!(
                    "{:>10} {:>10.1} {:>10} {:>8} {:>10.3} {:>14} {:>8}  {}\n",
                    r.force_pn,
                    r.reference_axial_um,
                    r.axial_um.map_or("-".into(), |v| format!("{v:.3}")),
                    percent(r.relative_difference),
                    r.reference_transverse_um,
                    r.transverse_um.map_or("-".into(), |v| format!("{v:.3}")),
                    percent(r.transverse_relative_difference),
                    r.failure.clone().unwrap_or_default()
                ));
            }
        }
        text
    });
    Ok(())
}

/// Arguments of `iuq rbc bench`.
#[derive(Debug, Args)]
pub struct BenchArgs {
    /// Steps per timing.
    #[arg(long, default_value_t = 200)]
    pub steps: usize,
    /// Timings (the best is reported).
    #[arg(long, default_value_t = 5)]
    pub repeats: usize,
    /// A box larger than the last-level cache, `NX,NY,NZ`, for the memory-bound figure
    /// (`0,0,0` to skip).
    #[arg(long, default_value = "160,160,64")]
    pub large: String,
    /// Size of the copied buffer for the bandwidth, in MB.
    #[arg(long, default_value_t = 512)]
    pub copy_mb: usize,
}

fn bench(args: &BenchArgs, json: bool) -> Result<()> {
    let large: Vec<usize> = args
        .large
        .split(',')
        .map(|s| s.trim().parse::<usize>())
        .collect::<std::result::Result<_, _>>()
        .map_err(|e| input_error(format!("--large: expected NX,NY,NZ: {e}")))?;
    if large.len() != 3 {
        return Err(input_error("--large: expected three sizes NX,NY,NZ"));
    }
    if args.steps == 0 || args.repeats == 0 || args.copy_mb == 0 {
        return Err(input_error(
            "--steps, --repeats and --copy-mb must be positive",
        ));
    }
    // A box of 4096³ nodes (19 populations of 8 bytes, two buffers) is 20 TB: larger is a typo.
    if large.iter().any(|&n| n > 4096) {
        return Err(input_error(format!(
            "--large: {}: each size at most 4096 nodes",
            args.large
        )));
    }
    if args.copy_mb > 1 << 20 {
        return Err(input_error(format!(
            "--copy-mb: {} MB is more than a terabyte",
            args.copy_mb
        )));
    }
    let copy_all = memory_copy_bandwidth(args.copy_mb << 20, args.repeats, true);
    let copy_one = memory_copy_bandwidth(args.copy_mb << 20, args.repeats, false);
    let mut rows: Vec<LatticeBenchmark> = Vec::new();
    for precision in [Precision::Single, Precision::Double] {
        for (parallel, copy) in [(true, copy_all), (false, copy_one)] {
            for forced in [false, true] {
                rows.push(benchmark_lattice(
                    SHEAR_DOMAIN,
                    args.steps,
                    args.repeats,
                    precision,
                    parallel,
                    forced,
                    copy,
                ));
            }
        }
    }
    if large.iter().all(|&n| n >= 3) {
        let domain = [large[0], large[1], large[2]];
        let steps = (args.steps * SHEAR_DOMAIN.iter().product::<usize>()
            / domain.iter().product::<usize>())
        .max(3);
        for precision in [Precision::Single, Precision::Double] {
            for (parallel, copy) in [(true, copy_all), (false, copy_one)] {
                rows.push(benchmark_lattice(
                    domain,
                    steps,
                    args.repeats.min(3),
                    precision,
                    parallel,
                    false,
                    copy,
                ));
            }
        }
    }
    let value = json!({
        "copy_bandwidth_gb_per_s": { "all_threads": copy_all, "one_thread": copy_one },
        "copy_buffer_mb": args.copy_mb,
        "threads": rayon::current_num_threads(),
        "runs": rows,
    });
    emit(json, &value, || {
        let mut text = format!(
            "memory copy bandwidth (read + write, {} MB buffer): {} GB/s on {} threads, {} GB/s on one\n",
            args.copy_mb,
            short(copy_all),
            rayon::current_num_threads(),
            short(copy_one)
        );
        text.push_str(&format!(
            "{:<14} {:<7} {:<9} {:>7} {:>7} {:>8} {:>8} {:>9}\n",
            "domain", "prec", "kernel", "threads", "MLUPS", "B/update", "GB/s", "fraction"
        ));
        for r in &rows {
            text.push_str(&format!(
                "{:<14} {:<7} {:<9} {:>7} {:>7.1} {:>8} {:>8.2} {:>8.0}%\n",
                format!("{}x{}x{}", r.domain[0], r.domain[1], r.domain[2]),
                r.precision,
                if r.forced { "forced" } else { "unforced" },
                r.threads,
                r.mlups,
                r.bytes_per_update,
                r.achieved_gb_per_s,
                100.0 * r.bandwidth_fraction
            ));
        }
        text
    });
    Ok(())
}
