//! The fluid solver's results pinned bit for bit.
//!
//! Each configuration the lattice supports (single and double storage, periodic z or moving
//! walls, no force, a body force or a local force with a changed relaxation rate) runs a few
//! hundred steps from a sheared start; an FNV-1a hash over the bits of the density and velocity
//! of every node, taken every 50 steps, must equal the value recorded from the solver. The
//! parallel, sequential and pool-worker sweeps must give the same hash, and so must every
//! instruction set: the test reruns itself with `IUQ_RBC_SIMD=avx2` and `=scalar`.
//!
//! A deliberate change of the numerics changes these constants; a refactoring must not.

use iuq_rbc::lattice::{Lattice, Precision, ZBoundary, on_pool_worker};

const STEPS: usize = 300;
const CHECKPOINT: usize = 50;

/// The variable that marks a rerun of this test under a forced instruction set.
const CHILD: &str = "IUQ_RBC_BIT_IDENTITY_CHILD";

#[derive(Debug, Clone, Copy)]
enum Forcing {
    None,
    Body,
    Local,
}

struct Fnv(u64);

impl Fnv {
    fn new() -> Self {
        Fnv(0xcbf2_9ce4_8422_2325)
    }

    fn add(&mut self, v: f64) {
        for byte in v.to_bits().to_le_bytes() {
            self.0 ^= u64::from(byte);
            self.0 = self.0.wrapping_mul(0x0100_0000_01b3);
        }
    }
}

fn boundaries() -> [(&'static str, ZBoundary); 3] {
    [
        ("periodic", ZBoundary::Periodic),
        (
            "moving walls",
            ZBoundary::Walls {
                bottom: [-0.004, 0.001, 0.0],
                top: [0.004, -0.002, 0.0],
            },
        ),
        (
            "resting walls",
            ZBoundary::Walls {
                bottom: [0.0; 3],
                top: [0.0; 3],
            },
        ),
    ]
}

fn lattice(boundary: ZBoundary, precision: Precision) -> Lattice {
    // nx = 13 leaves a partial vector at the end of each row for 4 and 8 lanes.
    let mut l = Lattice::new(13, 5, 7, boundary, 0.93, precision);
    l.set_equilibrium(|x, y, z| {
        let (x, y, z) = (x as f64, y as f64, z as f64);
        [
            0.01 * (0.9 * z + 0.3 * y).sin(),
            0.005 * (0.5 * x).cos(),
            0.003 * (0.7 * x + 0.2 * y).sin(),
        ]
    });
    l
}

fn hash_fields(l: &Lattice, h: &mut Fnv) {
    let g = *l.geometry();
    for z in 0..g.nz {
        for y in 0..g.ny {
            for x in 0..g.nx {
                let (rho, u) = l.velocity(x, y, z);
                h.add(rho);
                u.into_iter().for_each(|v| h.add(v));
                l.velocity_at(x, y, z).into_iter().for_each(|v| h.add(v));
            }
        }
    }
    h.add(l.total_mass());
}

fn run(l: &mut Lattice, forcing: Forcing) -> u64 {
    let mut h = Fnv::new();
    let local = [101, 102, 250, 377];
    match forcing {
        Forcing::None => {}
        Forcing::Body => l.fill_force([2e-6, -1e-6, 5e-7]),
        Forcing::Local => {
            l.set_omega(150, 1.0 / 3.5);
            l.set_omega(151, 1.0 / 3.5);
        }
    }
    for step in 0..STEPS {
        if let Forcing::Local = forcing {
            let s = step as f64;
            for (i, &node) in local.iter().enumerate() {
                let a = 1e-4 * (0.05 * s + i as f64).sin();
                l.add_force(node, [a, -0.5 * a, 0.25 * a]);
            }
        }
        l.step();
        if (step + 1) % CHECKPOINT == 0 || step + 1 == STEPS - 1 {
            hash_fields(l, &mut h);
        }
        if let Forcing::Local = forcing {
            if step % 2 == 0 {
                l.clear_forces();
            } else {
                l.clear_forces_at(local);
            }
        }
    }
    h.0
}

/// The hash of one configuration, checked to be the same for every way of sweeping.
fn configuration_hash(boundary: ZBoundary, precision: Precision, forcing: Forcing) -> u64 {
    let parallel = run(&mut lattice(boundary, precision), forcing);
    let mut sequential = lattice(boundary, precision);
    sequential.set_parallel(false);
    assert_eq!(run(&mut sequential, forcing), parallel, "sequential sweep");
    let pooled = on_pool_worker(|| run(&mut lattice(boundary, precision), forcing));
    assert_eq!(pooled, parallel, "sweep on a pool worker");
    parallel
}

/// Hashes recorded from the solver, in the order precision × boundary × forcing.
const RECORDED: [u64; 18] = [
    0x5432_feda_3898_1462,
    0x91ef_85b3_ea50_dde0,
    0xdf17_f96c_dedc_181e,
    0x2939_2b10_df2f_424f,
    0x3ba8_ae74_0d97_5e7d,
    0x2596_6c58_ad31_0fb0,
    0x90ee_8dd4_4873_e91a,
    0xa6c4_01f1_1511_facd,
    0x65a9_8496_5798_4e18,
    0x9027_51d3_a0ba_2279,
    0x7dad_bdae_7b7b_66de,
    0x1965_4486_f465_5d48,
    0xbc4a_78c7_8596_de60,
    0xe4e5_7782_a183_aad6,
    0x9874_81aa_cf8c_2974,
    0x9381_a328_e090_fc13,
    0x3d17_b15a_71c9_31be,
    0x9827_fd96_3867_4ee2,
];

#[test]
fn every_configuration_gives_the_recorded_bits() {
    let mut hashes = Vec::new();
    let mut index = 0;
    let mut mismatches = Vec::new();
    for precision in [Precision::Single, Precision::Double] {
        for (name, boundary) in boundaries() {
            for forcing in [Forcing::None, Forcing::Body, Forcing::Local] {
                let h = configuration_hash(boundary, precision, forcing);
                hashes.push(h);
                if h != RECORDED[index] {
                    mismatches.push(format!("{precision:?} {name} {forcing:?}: {h:#018x}"));
                }
                index += 1;
            }
        }
    }
    let instruction_set = lattice(ZBoundary::Periodic, Precision::Single).instruction_set();
    let table: Vec<String> = hashes.iter().map(|h| format!("{h:#018x}")).collect();
    assert!(
        mismatches.is_empty(),
        "on {instruction_set}: {mismatches:#?}\nall: [{}]",
        table.join(", ")
    );

    if std::env::var_os(CHILD).is_some() {
        let forced = std::env::var("IUQ_RBC_SIMD").unwrap_or_default();
        if forced == "scalar" {
            assert_eq!(instruction_set, "scalar");
        } else if forced == "avx2" && instruction_set != "scalar" {
            assert_eq!(instruction_set, "avx2+fma");
        }
        return;
    }
    if cfg!(target_arch = "x86_64") {
        for forced in ["avx2", "scalar"] {
            let exe = std::env::current_exe().expect("the test binary's path");
            let out = std::process::Command::new(exe)
                .args([
                    "--exact",
                    "every_configuration_gives_the_recorded_bits",
                    "--nocapture",
                    "--test-threads=1",
                ])
                .env(CHILD, "1")
                .env("IUQ_RBC_SIMD", forced)
                .output()
                .expect("the test binary runs");
            assert!(
                out.status.success(),
                "IUQ_RBC_SIMD={forced}:\n{}\n{}",
                String::from_utf8_lossy(&out.stdout),
                String::from_utf8_lossy(&out.stderr)
            );
        }
    }
}
