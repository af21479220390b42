//! End-to-end tests of the coupled simulator.
//!
//! The fast tests run a few hundred to a few thousand steps. The long ones are `#[ignore]`d;
//! run them with
//! `cargo test --release -p iuq-rbc --test shear_experiment -- --ignored --nocapture`
//! (the validation tables take tens of minutes on two cores; `iuq rbc validate` runs the same).

use iuq_core::Model;
use iuq_rbc::lattice::Precision;
use iuq_rbc::membrane_forces::{MembraneParameters, PastSingularity};
use iuq_rbc::model::{RbcShearModel, RbcShearSettings};
use iuq_rbc::protocol::{Protocol, ShearExperiment, run_shear, shear_cell};
use iuq_rbc::validation::{HEMOCELL_EL, validate_shear, validate_stretch};

fn cell(k_link: f64) -> MembraneParameters {
    MembraneParameters {
        k_link,
        k_bend: 367.0,
        ..Default::default()
    }
}

/// Largest edge strain after `steps` steps of the scaled protocol.
fn link_strain_after(k_link: f64, stress: f64, steps: u64) -> f64 {
    let e = ShearExperiment::new(cell(k_link), 5.9, stress);
    let setup = e.setup();
    let mut c = shear_cell(&e, &setup).unwrap();
    for _ in 0..steps {
        c.step().unwrap();
    }
    c.strain().max_link_strain
}

#[test]
fn deformation_rises_with_stress_and_falls_with_k_link() {
    // A short version of the monotonicity check: after the same strain (1000 steps, γ̇t = 0.3)
    // the membrane is stretched more at a higher capillary number.
    let base = link_strain_after(36.7, 1.36, 1000);
    let harder_flow = link_strain_after(36.7, 4.24, 1000);
    let stiffer_cell = link_strain_after(150.0, 1.36, 1000);
    assert!(harder_flow > base * 1.2, "{harder_flow} vs {base}");
    assert!(stiffer_cell < base / 1.2, "{stiffer_cell} vs {base}");
}

#[test]
fn threads_do_not_change_a_run() {
    let mut a = ShearExperiment::new(cell(36.7), 5.9, 2.0);
    a.start_strain = 0.06;
    a.frames = 3;
    let mut b = a.clone();
    a.parallel = true;
    b.parallel = false;
    let (ra, rb) = (run_shear(&a).unwrap(), run_shear(&b).unwrap());
    assert_eq!(ra.el_frames(), rb.el_frames());
    assert_eq!(ra.frames[2].vertices, rb.frames[2].vertices);
}

#[test]
fn the_model_evaluates_a_batch_with_stds_and_per_point_failures() {
    let settings = RbcShearSettings {
        start_strain: 0.05,
        frames: 3,
        ..Default::default()
    };
    let names = ["kLink", "kBend", "viscosityRatio"]
        .map(String::from)
        .to_vec();
    let model = RbcShearModel::new(names, vec![1.0, 3.0], settings).unwrap();
    let points = vec![
        vec![36.7, 367.0, 5.9],
        vec![-1.0, 80.0, 5.0],
        vec![100.0, 80.0, 2.0],
    ];
    let out = model.evaluate_batch(&points).unwrap();
    assert_eq!(out.len(), 3);
    for k in [0, 2] {
        let e = out[k].as_ref().unwrap();
        assert_eq!(e.outputs.len(), 2);
        let stds = e.computational_std.as_ref().unwrap();
        assert!(
            e.outputs
                .iter()
                .all(|v| v.is_finite() && *v >= 0.0 && *v < 1.0)
        );
        assert!(stds.iter().all(|v| v.is_finite() && *v >= 0.0));
    }
    assert!(out[1].as_ref().unwrap_err().reason.contains("kLink"));
}

#[test]
#[ignore = "long: 3 full scaled-protocol runs (~1-2 min on two cores)"]
fn elongation_index_rises_with_stress_and_falls_with_k_link() {
    let run = |k_link: f64, stress: f64| {
        let r = run_shear(&ShearExperiment::new(cell(k_link), 5.9, stress));
        println!(
            "kLink {k_link} stress {stress}: {r:?}",
            r = r.as_ref().map(|r| (r.el_mean, r.el_std))
        );
        r.map(|r| r.el_mean)
    };
    let base = run(100.0, 0.93).unwrap();
    let harder_flow = run(100.0, 2.91).unwrap();
    let stiffer_cell = run(250.0, 0.93).unwrap();
    assert!(harder_flow > base, "{harder_flow} vs {base}");
    assert!(stiffer_cell < base, "{stiffer_cell} vs {base}");
}

#[test]
#[ignore = "long: one scaled-protocol run in single and one in double precision"]
fn single_precision_storage_gives_the_double_precision_elongation() {
    let mut a = ShearExperiment::new(cell(36.7), 5.9, 0.93);
    a.precision = Precision::Single;
    let mut b = a.clone();
    b.precision = Precision::Double;
    let (ra, rb) = (run_shear(&a).unwrap(), run_shear(&b).unwrap());
    println!("single {:?}\ndouble {:?}", ra.el_frames(), rb.el_frames());
    assert!((ra.el_mean - rb.el_mean).abs() < 0.01 * rb.el_mean.max(0.01));
}

/// HemoCell's validation cell at 6.19 Pa: one triangle reaches the area singularity at step
/// ≈ 13,000; as in HemoCell the run carries on (the default) and its EL lies within 5 % of
/// HemoCell's 0.492 (measured 0.4765, −3.2 %), while `PastSingularity::Fail` fails it.
#[test]
#[ignore = "long: two scaled-protocol runs at 6.19 Pa (about a minute each on 2 cores)"]
fn the_validation_cell_at_6_19_pa_carries_on_past_the_area_singularity_as_hemocell_does() {
    let hemocell = ShearExperiment::new(cell(36.7), 5.9, 6.19);
    assert_eq!(hemocell.past_singularity, PastSingularity::CarryOn);
    let failing = ShearExperiment {
        past_singularity: PastSingularity::Fail,
        ..hemocell.clone()
    };
    let err = run_shear(&failing).unwrap_err();
    assert!(err.to_string().contains("singularity"), "{err}");
    let r = run_shear(&hemocell).unwrap();
    println!("carry-on at 6.19 Pa: {:?}", r.el_frames());
    assert!((r.el_mean - 0.492).abs() < 0.05 * 0.492, "{}", r.el_mean);
}

fn print_shear_table(protocol: Protocol) {
    for r in validate_shear(protocol, PastSingularity::CarryOn) {
        println!(
            "{:<9} {:>5} Pa  HemoCell {:.3}  here {}  {}",
            r.protocol,
            r.stress,
            r.hemocell,
            r.el_mean.map_or("-".to_string(), |v| format!(
                "{v:.4} ± {:.4}",
                r.el_std.unwrap_or(0.0)
            )),
            r.relative_difference
                .map_or(r.failure.clone().unwrap_or_default(), |d| format!(
                    "{:+.1} %",
                    100.0 * d
                ))
        );
    }
}

#[test]
#[ignore = "validation: seven scaled-protocol runs (several minutes on two cores)"]
fn validation_table_scaled_protocol() {
    assert_eq!(HEMOCELL_EL.len(), 7);
    print_shear_table(Protocol::default());
}

#[test]
#[ignore = "validation: seven reference-protocol runs (up to 330k steps each, about a million in all)"]
fn validation_table_reference_protocol() {
    print_shear_table(Protocol::Reference);
}

#[test]
#[ignore = "validation: four stretching runs to equilibrium (a few minutes)"]
fn validation_optical_tweezers_stretching() {
    for r in validate_stretch() {
        println!("{r:?}");
        assert!(r.failure.is_none());
    }
}
