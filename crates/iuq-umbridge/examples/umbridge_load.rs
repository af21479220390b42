//! Load check of a UM-Bridge server: `--clients` concurrent clients (each a thread with its own
//! kept-alive connection) send `--requests` `/Evaluate` requests in total at quasi-random points
//! of a box, and every answer is checked (status 200, an `output` of the declared sizes).
//!
//! ```text
//! cargo run --release -p iuq-umbridge --example umbridge_load -- URL MODEL \
//!     --bounds 10:300,50:400,1:15 [--requests 1000] [--clients 8]
//! ```
//!
//! Prints one JSON object: requests, answered, ok, errors (by kind), seconds,
//! requests_per_second, latency percentiles in milliseconds. Used by
//! `scripts/bench/umbridge_load.py`, which runs it against `iuq serve umbridge` and against the
//! Python package's server.

use std::collections::BTreeMap;
use std::process::ExitCode;
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use iuq_umbridge::protocol;

struct Settings {
    url: String,
    model: String,
    bounds: Vec<(f64, f64)>,
    requests: usize,
    clients: usize,
}

fn parse_args() -> Result<Settings, String> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mut positional = Vec::new();
    let mut bounds = None;
    let mut requests = 1000;
    let mut clients = 8;
    let mut i = 0;
    while i < args.len() {
        let value = || {
            args.get(i + 1)
                .cloned()
                .ok_or(format!("{} needs a value", args[i]))
        };
        match args[i].as_str() {
            "--bounds" => {
                let text = value()?;
                let parsed = text
                    .split(',')
                    .map(|pair| {
                        let (lo, hi) = pair.split_once(':')?;
                        Some((lo.parse().ok()?, hi.parse().ok()?))
                    })
                    .collect::<Option<Vec<(f64, f64)>>>()
                    .ok_or(format!("--bounds: expected lo:hi,lo:hi,…, got {text}"))?;
                bounds = Some(parsed);
                i += 2;
            }
            "--requests" => {
                requests = value()?.parse().map_err(|e| format!("--requests: {e}"))?;
                i += 2;
            }
            "--clients" => {
                clients = value()?.parse().map_err(|e| format!("--clients: {e}"))?;
                i += 2;
            }
            other => {
                positional.push(other.to_string());
                i += 1;
            }
        }
    }
    let [url, model] = positional.as_slice() else {
        return Err(
            "usage: umbridge_load URL MODEL --bounds lo:hi,… [--requests N] [--clients C]".into(),
        );
    };
    if clients == 0 {
        return Err("--clients must be at least 1".into());
    }
    Ok(Settings {
        url: url.trim_end_matches('/').to_string(),
        model: model.clone(),
        bounds: bounds.ok_or("--bounds is required")?,
        requests,
        clients,
    })
}

/// Point i of the additive recurrence with the generalised golden ratio (R_d), in the box.
fn point(i: usize, bounds: &[(f64, f64)]) -> Vec<f64> {
    let d = bounds.len();
    // φ_d: the positive root of x^(d+1) = x + 1.
    let mut phi = 2.0f64;
    for _ in 0..30 {
        phi = (1.0 + phi).powf(1.0 / (d as f64 + 1.0));
    }
    bounds
        .iter()
        .enumerate()
        .map(|(k, (lo, hi))| {
            let alpha = phi.powi(-(k as i32 + 1));
            let u = (0.5 + alpha * (i as f64 + 1.0)).fract();
            lo + u * (hi - lo)
        })
        .collect()
}

fn percentile(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let rank = (q * (sorted.len() - 1) as f64).round() as usize;
    sorted[rank.min(sorted.len() - 1)]
}

fn main() -> ExitCode {
    let settings = match parse_args() {
        Ok(s) => s,
        Err(e) => {
            eprintln!("{e}");
            return ExitCode::from(2);
        }
    };
    let config = ureq::Agent::config_builder()
        .http_status_as_error(false)
        .build();
    let agent: ureq::Agent = config.into();
    let sizes_request = protocol::sizes_request(&settings.model, &serde_json::json!({}));
    let output_sizes = agent
        .post(format!("{}/OutputSizes", settings.url))
        .send(sizes_request.as_str())
        .ok()
        .and_then(|r| r.into_body().read_to_string().ok())
        .and_then(|b| protocol::parse_sizes(&b, "outputSizes").ok());
    let Some(output_sizes) = output_sizes else {
        eprintln!(
            "cannot read the output sizes of `{}` at {}",
            settings.model, settings.url
        );
        return ExitCode::from(1);
    };

    let next = AtomicUsize::new(0);
    let errors: Mutex<BTreeMap<String, usize>> = Mutex::new(BTreeMap::new());
    let latencies: Mutex<Vec<f64>> = Mutex::new(Vec::with_capacity(settings.requests));
    let ok = AtomicUsize::new(0);
    let record_error = |kind: String| {
        if let Ok(mut e) = errors.lock() {
            *e.entry(kind).or_insert(0) += 1;
        }
    };
    let started = Instant::now();
    std::thread::scope(|scope| {
        for _ in 0..settings.clients {
            scope.spawn(|| {
                let agent: ureq::Agent = ureq::Agent::config_builder()
                    .http_status_as_error(false)
                    .build()
                    .into();
                let url = format!("{}/Evaluate", settings.url);
                let mut mine = Vec::new();
                loop {
                    let i = next.fetch_add(1, Ordering::SeqCst);
                    if i >= settings.requests {
                        break;
                    }
                    let x = point(i, &settings.bounds);
                    let body =
                        protocol::evaluate_request(&settings.model, &[x], &serde_json::json!({}));
                    let t = Instant::now();
                    let answer = agent
                        .post(&url)
                        .header("Content-Type", "application/json")
                        .send(body.as_str());
                    let response = match answer {
                        Ok(r) => r,
                        Err(e) => {
                            record_error(format!("transport: {e}"));
                            continue;
                        }
                    };
                    let status = response.status().as_u16();
                    let text = response.into_body().read_to_string();
                    mine.push(t.elapsed().as_secs_f64() * 1e3);
                    match (status, text) {
                        (200, Ok(text)) => match protocol::parse_output_lists(&text) {
                            Ok(out)
                                if protocol::check_sizes(&out, &output_sizes, "output").is_ok() =>
                            {
                                ok.fetch_add(1, Ordering::SeqCst);
                            }
                            _ => record_error("invalid output".into()),
                        },
                        (status, _) => record_error(format!("HTTP {status}")),
                    }
                }
                if let Ok(mut all) = latencies.lock() {
                    all.extend(mine);
                }
            });
        }
    });
    let seconds = started.elapsed().as_secs_f64();
    let mut latencies = latencies.into_inner().unwrap_or_default();
    latencies.sort_by(f64::total_cmp);
    let errors = errors.into_inner().unwrap_or_default();
    let ok = ok.into_inner();
    let summary = serde_json::json!({
        "url": settings.url,
        "model": settings.model,
        "requests": settings.requests,
        "clients": settings.clients,
        "answered": latencies.len(),
        "ok": ok,
        "errors": errors,
        "seconds": seconds,
        "requests_per_second": settings.requests as f64 / seconds,
        "latency_ms": {
            "mean": latencies.iter().sum::<f64>() / latencies.len().max(1) as f64,
            "p50": percentile(&latencies, 0.5),
            "p90": percentile(&latencies, 0.9),
            "p99": percentile(&latencies, 0.99),
            "max": latencies.last().copied().unwrap_or(f64::NAN),
        },
    });
    println!("{summary}");
    if ok == settings.requests {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(1)
    }
}
