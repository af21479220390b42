//! The floor of a local campaign: start a command N times, P at a time, the way the local
//! executor starts it (std's `Command`, i.e. posix_spawn, in the command's folder, waited for),
//! with no run directories, templates, decoding or store. Prints the wall time in seconds.
//!
//! Usage: `spawn_floor N P DIR PROGRAM [ARGS…]` (used by scripts/bench/campaign_local.py).

use std::process::{Command, ExitCode, Stdio};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (Some(n), Some(p), Some(dir), Some(program)) = (
        args.first().and_then(|a| a.parse::<usize>().ok()),
        args.get(1).and_then(|a| a.parse::<usize>().ok()),
        args.get(2),
        args.get(3),
    ) else {
        eprintln!("usage: spawn_floor N P DIR PROGRAM [ARGS...]");
        return ExitCode::from(2);
    };
    let rest = &args[4..];
    let next = AtomicUsize::new(0);
    let start = Instant::now();
    std::thread::scope(|s| {
        for _ in 0..p.max(1) {
            s.spawn(|| {
                while next.fetch_add(1, Ordering::Relaxed) < n {
                    let _ = Command::new(program)
                        .args(rest)
                        .current_dir(dir)
                        .stdin(Stdio::null())
                        .stdout(Stdio::null())
                        .stderr(Stdio::null())
                        .status();
                }
            });
        }
    });
    println!("{}", start.elapsed().as_secs_f64());
    ExitCode::SUCCESS
}
