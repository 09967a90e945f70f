//! The small commands: `synth`, `view` and `demo`, wired over the library's stages.

use std::net::IpAddr;
use std::path::Path;

use crate::error::{Error, Result};
use crate::synth::campaign::{self, CampaignOptions};
use crate::synth::{SceneKind, SynthOptions};

/// `talus synth SCENE --out DIR` (SCENE `campaign`: `--epochs` surveys, no `--rotate`,
/// `--density2` or `--shift`).
#[allow(clippy::too_many_arguments)]
pub fn synth(
    scene: &str,
    out: &Path,
    points: Option<u64>,
    epochs: Option<usize>,
    seed: u64,
    noise: Option<f64>,
    rotate: f64,
    density2: f64,
    shift: [f64; 3],
    laz: bool,
) -> Result<()> {
    if scene.trim().eq_ignore_ascii_case("campaign") {
        if rotate != 0.0 || density2 != 1.0 || shift != [0.0; 3] {
            return Err(Error::Usage(
                "synth campaign: --rotate, --density2 and --shift are for the pair scenes".into(),
            ));
        }
        let opts = CampaignOptions {
            epochs: epochs.unwrap_or(campaign::DEFAULT_EPOCHS),
            seed,
            points,
            noise,
            laz,
        };
        let truth = campaign::write(out, &opts)?;
        let events: usize = truth.pairs.iter().map(|p| p.events.len()).sum();
        let (first, last) = (&truth.epochs[0], &truth.epochs[truth.epochs.len() - 1]);
        println!(
            "campaign: {} surveys ({} to {}) of {} points, {events} planted event(s) over {} \
             intervals, truth in {}",
            truth.epochs.len(),
            first.date,
            last.date,
            first.points,
            truth.pairs.len(),
            out.join("truth.json").display()
        );
        return Ok(());
    }
    if epochs.is_some() {
        return Err(Error::Usage(
            "synth: --epochs is for `synth campaign`".into(),
        ));
    }
    let kind: SceneKind = scene.parse()?;
    let opts = SynthOptions {
        points,
        seed,
        noise,
        rotate_deg: rotate,
        density2,
        shift_m: shift,
        laz,
    };
    let truth = crate::synth::synth(kind, &opts, out)?;
    println!(
        "{}: {} + {} points, {} planted event(s), truth in {}",
        truth.scene,
        truth.points[0],
        truth.points[1],
        truth.events.len(),
        out.join("truth.json").display()
    );
    Ok(())
}

/// `talus view DIR`.
pub fn view(dir: &Path, bind: IpAddr, port: u16) -> Result<()> {
    // Serving has nothing to resume: Ctrl-C or SIGTERM end it at once.
    crate::interrupt::uninstall();
    crate::view::serve(dir, bind, port, &crate::view::Viewer::from_env(), |addr| {
        println!("talus viewer: http://{addr}/");
        use std::io::Write;
        let _ = std::io::stdout().flush();
    })
}

/// `talus demo`: synthesize the cliff scene, compare it with derived parameters only, and print
/// each event beside the planted truth it matches (nearest centre of the same kind).
pub fn demo(out: &Path, view: bool) -> Result<()> {
    let scene = out.join("scene");
    let result = out.join("result");
    let truth = crate::synth::synth(SceneKind::Cliff, &SynthOptions::default(), &scene)?;
    let opts = crate::compare::CompareOptions {
        before: scene.join(&truth.epochs[0]),
        after: scene.join(&truth.epochs[1]),
        out: result.clone(),
        force: true,
        ..Default::default()
    };
    let summary = crate::compare::compare(&opts)?
        .ok_or_else(|| Error::Internal("demo: no summary".into()))?;
    let text = std::fs::read_to_string(result.join("events.geojson"))
        .map_err(|e| Error::Internal(format!("events.geojson: {e}")))?;
    let fc: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| Error::Internal(e.to_string()))?;
    println!(
        "talus demo: {} — {} + {} points, {} planted change(s)",
        truth.summary,
        truth.points[0],
        truth.points[1],
        truth.events.len()
    );
    println!(
        "{:>3}  {:<5} {:>20}  {:>34}  {:>10}  {:>7}",
        "id", "kind", "volume m³", "centre (x, y, z)", "truth m³", "error"
    );
    let empty = vec![];
    for f in fc["features"].as_array().unwrap_or(&empty) {
        let p = &f["properties"];
        let c: Vec<f64> = f["geometry"]["coordinates"]
            .as_array()
            .map(|a| a.iter().filter_map(|v| v.as_f64()).collect())
            .unwrap_or_default();
        let kind = p["kind"].as_str().unwrap_or("?");
        let v = p["volume_m3"].as_f64();
        let u = p["volume_uncertainty_m3"].as_f64().unwrap_or(f64::NAN);
        let matched = truth
            .events
            .iter()
            .filter(|t| t.kind == kind && c.len() == 3)
            .min_by(|a, b| {
                let d = |t: &&crate::synth::TruthEvent| {
                    (t.centre[0] - c[0]).powi(2)
                        + (t.centre[1] - c[1]).powi(2)
                        + (t.centre[2] - c[2]).powi(2)
                };
                d(a).total_cmp(&d(b))
            });
        let (tv, err) = match (matched, v) {
            (Some(t), Some(v)) => (
                format!("{:+.3}", t.volume_m3),
                format!("{:+.2} %", 100.0 * (v - t.volume_m3) / t.volume_m3.abs()),
            ),
            _ => ("-".into(), "-".into()),
        };
        println!(
            "{:>3}  {:<5} {:>20}  {:>34}  {:>10}  {:>7}",
            p["id"].as_u64().unwrap_or(0),
            kind,
            v.map(|v| format!("{v:+.3} ± {u:.3}"))
                .unwrap_or_else(|| "-".into()),
            if c.len() == 3 {
                format!("{:.2}, {:.2}, {:.2}", c[0], c[1], c[2])
            } else {
                "-".into()
            },
            tv,
            err
        );
    }
    println!(
        "{} core points, {} tile(s); outputs in {} (m3c2.laz, events.geojson, event_regions.geojson, events.csv, meshes/, summary.json)",
        summary.core_points,
        summary.tiles,
        result.display()
    );
    if view {
        return self::view(&result, crate::view::DEFAULT_BIND, 0);
    }
    println!("see them with: talus view {}", result.display());
    Ok(())
}

/// `talus worker DIR`: execute units of the run in DIR until every unit is done (the process
/// that holds DIR's lock publishes).
pub fn worker(dir: &Path, slots: usize, threads: Option<usize>) -> Result<()> {
    if slots == 0 {
        return Err(Error::Usage(
            "--slots: must be at least 1 (units the worker runs at a time)".into(),
        ));
    }
    let store = crate::store::Store::open(dir, false)?;
    let plan = crate::plan::Plan::load(&crate::compare::plan_path(&store))?;
    let threads = match threads {
        Some(0) => return Err(Error::Usage("--threads: must be at least 1".into())),
        Some(t) => t.min(1024),
        None => std::thread::available_parallelism().map_or(1, |n| n.get()),
    };
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map_err(|e| Error::Internal(format!("thread pool: {e}")))?;
    let label = format!("worker {}", std::process::id());
    let report = pool.install(|| crate::exec::run(&store, &plan, slots, &label))?;
    eprintln!(
        "talus worker: {} unit(s) computed, {} found done, in {}",
        report.computed,
        report.reused,
        dir.display()
    );
    Ok(())
}
