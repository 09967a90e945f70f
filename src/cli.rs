//! The command line: argument parsing, error printing and exit codes over the commands. The
//! `talus` binary is [`main`]; a program with a stage of its own registers it, then calls
//! [`main`] too (`examples/survey_stage.rs`).

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Args, Parser, Subcommand};

use crate::params::UserParams;

#[derive(Parser)]
#[command(
    name = "talus",
    version = concat!(env!("CARGO_PKG_VERSION"), " (commit ", env!("TALUS_COMMIT"), ")"),
    about = "Change events and their volumes between two terrain surveys (M3C2, out-of-core tiles)"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Compare two epochs: M3C2 distances, change events and their volumes.
    Compare(Box<CompareArgs>),
    /// Compare the surveys of a campaign pair by pair: tables, tracks, time series, report.
    Campaign(Box<CampaignArgs>),
    /// Point count, bounds, format, CRS, point spacing and derived parameters of point clouds.
    Info {
        /// Point clouds (LAS/LAZ, text, PLY).
        #[arg(required = true)]
        files: Vec<PathBuf>,
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
    },
    /// Write a synthetic pair of epochs (or a campaign of surveys) with exact ground truth
    /// (truth.json).
    Synth(SynthArgs),
    /// Serve the web viewer for a comparison or campaign result on 127.0.0.1.
    View {
        /// A directory written by `talus compare` or `talus campaign` (or a campaign's
        /// pairs/<pair>).
        dir: PathBuf,
        /// Port (0 picks a free one).
        #[arg(long, default_value_t = 8080)]
        port: u16,
        /// Address to bind (default loopback only).
        #[arg(long, default_value = "127.0.0.1")]
        bind: std::net::IpAddr,
    },
    /// Execute units of the run in DIR (started by `talus compare` or `talus campaign`) beside
    /// the process that runs it: any number of workers, on this or other machines sharing DIR.
    Worker {
        /// The --out directory of a running comparison or campaign.
        dir: PathBuf,
        /// Units at a time.
        #[arg(long, default_value_t = 1)]
        slots: usize,
        /// Threads inside a unit (default: available cores).
        #[arg(long)]
        threads: Option<usize>,
    },
    /// The units of the run in DIR: done, running, queued, failed, by stage, with the Slurm job
    /// ids of its latest submission.
    Status {
        /// The --out directory of a run.
        dir: PathBuf,
    },
    /// One task of a Slurm job array (what the sbatch scripts of `--executor slurm` run).
    #[command(hide = true)]
    SlurmTask {
        dir: PathBuf,
        /// The submission's number (DIR/.talus/slurm/N).
        #[arg(long)]
        submission: u32,
        /// The stage: tiling, align, aligned, cleared, field, orient, cores, thinned, m3c2,
        /// merged, sampled, stable, kept, events, series, volumes, segments, points,
        /// outputs, campaign, publish.
        #[arg(long)]
        stage: String,
        /// The task (default: SLURM_ARRAY_TASK_ID).
        #[arg(long)]
        task: Option<usize>,
    },
    /// Scaling on paper: a finished run's stages as job arrays (tasks, work, memory from the
    /// units' records) and the wall time expected on some numbers of nodes.
    #[command(hide = true)]
    PlanStats {
        dir: PathBuf,
        /// Node counts, comma-separated.
        #[arg(long, default_value = "1,4,16", value_delimiter = ',')]
        nodes: Vec<usize>,
        /// Cores per node (one-CPU tasks per node).
        #[arg(long, default_value_t = 2)]
        cores: usize,
        /// Extrapolate to an input this many times bigger, linearly per tile.
        #[arg(long, default_value_t = 1.0)]
        scale: f64,
    },
    /// Synthesize the cliff scene, compare it and print the events beside the truth.
    Demo {
        /// Where to write the scene and the result.
        #[arg(long, default_value = "talus-demo")]
        out: PathBuf,
        /// Serve the viewer on the result afterwards.
        #[arg(long)]
        view: bool,
    },
}

/// The method's parameters (every one left out is derived from the data).
#[derive(Args)]
struct ParamArgs {
    /// Effective point spacing s the other parameters derive from, in the input's units
    /// (default: measured on the before survey — a campaign's first — as 1/√density).
    #[arg(long, value_name = "M")]
    point_spacing: Option<f64>,
    /// Distance between core points, where M3C2 distances are computed (default: 2 s).
    #[arg(long, value_name = "M")]
    core_spacing: Option<f64>,
    /// Radius of the neighbourhood a normal is fitted to (default: 4 s, about 50 points).
    #[arg(long, value_name = "M")]
    normal_radius: Option<f64>,
    /// Radius of M3C2's cylinder along the normal (default: 3 s, about 28 points per epoch).
    #[arg(long, value_name = "M")]
    cyl_radius: Option<f64>,
    /// Half-length of M3C2's cylinder (default: 10 × cyl_radius, a search window: deeper change
    /// is followed along the normal). Given, it is kept: the other survey beyond it is flagged,
    /// not measured.
    #[arg(long, value_name = "M")]
    cyl_halflen: Option<f64>,
    /// Registration error between the epochs, in the input's units (default: measured on the
    /// stable ground).
    #[arg(long, value_name = "M")]
    reg_error: Option<f64>,
    /// Fewer points than this in either cylinder → no distance (default: 1).
    #[arg(long, value_name = "N")]
    min_points: Option<u32>,
    /// LAS classes compared: all, or a list of class numbers to keep, e.g. 2,6,9 (default:
    /// every class but vegetation 3, 4, 5 and noise 7, 18).
    #[arg(long, value_name = "LIST|all")]
    classes: Option<String>,
    /// Stable areas you know, as GeoJSON polygons in the surveys' CRS: the stable ground (σ_d,
    /// reg_error, τ and the alignment) is the core points inside them (default: found in the
    /// distances).
    #[arg(long, value_name = "AREAS.geojson")]
    stable: Option<PathBuf>,
    /// Normal orientation: auto | up | X,Y,Z | toward:X,Y,Z (default: auto: up where not
    /// steep, toward the lower terrain on steep faces).
    #[arg(long)]
    orientation: Option<String>,
    /// Align the later survey onto the earlier (a campaign's onto its first) by a rigid
    /// transform fitted on the stable ground: auto (applied when significant, well constrained,
    /// confirmed on held-out ground and a plausible misregistration: at most 1 m and 0.5°; a
    /// larger one stops the run with what to do) | on (applied whatever its size, up to 100 m
    /// and 20°) | off (default: auto).
    #[arg(long, value_name = "auto|on|off")]
    align: Option<String>,
    /// Vegetation, recognised from the LAS classes and, for unclassified points, from its
    /// volumetric scatter: flag (its events are listed but left out of totals and tracks) |
    /// keep (they count like any other) | remove (vegetation-like points are dropped before
    /// M3C2) (default: flag).
    #[arg(long, value_name = "keep|flag|remove")]
    vegetation: Option<String>,
    /// Significance threshold τ on |distance|, in the input's units (default: 3 σ_d + 1.96
    /// reg_error from the stable ground).
    #[arg(long, value_name = "M")]
    threshold: Option<f64>,
    /// Neighbours of the normalised Gaussian smoothing of the distances (default: 30).
    #[arg(long, value_name = "N")]
    smooth_k: Option<u32>,
    /// Standard deviation of the smoothing kernel, in the input's units (default: 2 ×
    /// core_spacing).
    #[arg(long, value_name = "M")]
    smooth_sigma: Option<f64>,
    /// DBSCAN neighbourhood radius, in the input's units (default: 2.5 × core_spacing).
    #[arg(long, value_name = "M")]
    eps: Option<f64>,
    /// DBSCAN minimum points of a cluster (default: 10).
    #[arg(long, value_name = "N")]
    cluster_min_points: Option<u32>,
    /// Memory budget for the whole process, e.g. 2GiB, 512MiB (default: 2 GiB).
    #[arg(long, value_name = "SIZE")]
    memory: Option<String>,
    /// Worker threads (default: the available cores; the results do not depend on it).
    #[arg(long, value_name = "N")]
    threads: Option<usize>,
}

/// Where the units run (SPEC.md §6).
#[derive(Args)]
struct ExecArgs {
    /// local: this machine; slurm: sbatch job arrays on a Slurm cluster whose nodes share DIR.
    #[arg(long, default_value = "local", value_parser = ["local", "slurm"])]
    executor: String,
    /// (slurm) Wait for the last job and exit with the run's status.
    #[arg(long)]
    wait: bool,
    /// Keep the intermediate units (tiles, M3C2 results) after the run: a later run with new
    /// event or volume parameters then starts from them. By default their files are released
    /// once the outputs are published, and computed again when a later run needs them.
    #[arg(long)]
    keep_units: bool,
    /// (slurm) Arguments for every sbatch, e.g. "-p long -A geo --time=1:00:00".
    #[arg(long, allow_hyphen_values = true, value_name = "ARGS")]
    slurm_args: Option<String>,
    /// (slurm) Write the plan and the sbatch scripts into DIR/.talus/slurm/N, submit nothing.
    #[arg(long)]
    plan_only: bool,
    /// (slurm) Tiles per array task in the tile stages (M3C2, volumes) (default: 1).
    #[arg(long, value_name = "N")]
    tiles_per_task: Option<usize>,
    /// Points a tiling unit reads at most: a larger LAS/LAZ survey is tiled by several units,
    /// ranges of its points, a task each on a cluster (default: 8388608 with --executor slurm;
    /// a local run tiles each survey whole). The points a tile holds, and every output, are the
    /// same whatever it is.
    #[arg(long, value_name = "N")]
    tiling_part: Option<u64>,
}

impl ExecArgs {
    fn executor(&self) -> crate::Result<crate::exec::Executor> {
        // Refused whatever the executor (it was ignored locally, 0 and all).
        if self.tiles_per_task == Some(0) {
            return Err(crate::Error::Usage(
                "--tiles-per-task: must be at least 1".into(),
            ));
        }
        if self.tiling_part == Some(0) {
            return Err(crate::Error::Usage(
                "--tiling-part: must be at least 1".into(),
            ));
        }
        if self.executor == "local" {
            if self.wait || self.slurm_args.is_some() || self.plan_only {
                return Err(crate::Error::Usage(
                    "--wait, --slurm-args and --plan-only go with --executor slurm".into(),
                ));
            }
            if self.tiles_per_task.is_some() {
                return Err(crate::Error::Usage(
                    "--tiles-per-task goes with --executor slurm (a local run takes every tile \
                     as it comes)"
                        .into(),
                ));
            }
            return Ok(crate::exec::Executor::Local);
        }
        if self.wait && self.plan_only {
            return Err(crate::Error::Usage(
                "--wait and --plan-only: a plan only is not submitted, there is nothing to wait for"
                    .into(),
            ));
        }
        Ok(crate::exec::Executor::Slurm(crate::exec::slurm::Options {
            args: crate::exec::slurm::split_args(self.slurm_args.as_deref().unwrap_or(""))?,
            wait: self.wait,
            plan_only: self.plan_only,
            tiles_per_task: self.tiles_per_task.unwrap_or(1),
        }))
    }
}

#[derive(Args)]
struct CompareArgs {
    /// The earlier epoch (C1): a point cloud, or a folder or pattern of its tiles.
    before: PathBuf,
    /// The later epoch (C2), likewise.
    after: PathBuf,
    /// Output directory.
    #[arg(long)]
    out: PathBuf,
    /// TOML file with parameters (flags override it).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Core points file (any supported cloud format); default: C1 thinned by --core-spacing
    /// (with a file, --core-spacing is the spacing of its points: event areas, derived eps).
    #[arg(long)]
    core_points: Option<PathBuf>,
    #[command(flatten)]
    params: ParamArgs,
    #[command(flatten)]
    exec: ExecArgs,
    /// Continue an interrupted run in DIR.
    #[arg(long, conflicts_with = "force")]
    resume: bool,
    /// Start over: throw away DIR's talus run and outputs (never files talus did not write).
    #[arg(long)]
    force: bool,
    /// Use this PLY surface for C1 instead of the local reconstruction.
    #[arg(long)]
    before_mesh: Option<PathBuf>,
    /// Use this PLY surface for C2 instead of the local reconstruction.
    #[arg(long)]
    after_mesh: Option<PathBuf>,
    /// Stop after M3C2 (m3c2.laz, summary.json): no events, volumes or meshes.
    #[arg(long)]
    m3c2_only: bool,
    /// Tile side (for testing tiling invariance; default: planned from --memory).
    #[arg(long, hide = true)]
    tile_size: Option<f64>,
}

#[derive(Args)]
struct CampaignArgs {
    /// The surveys: point clouds, or folders or patterns of tiles, dated by YYYYMMDD or
    /// YYYY-MM-DD in their names or by [[epoch]] entries of --config.
    #[arg(required = true, num_args = 2..)]
    epochs: Vec<PathBuf>,
    /// Output directory.
    #[arg(long)]
    out: PathBuf,
    /// TOML file with parameters and [[epoch]] entries (path, date, label).
    #[arg(long)]
    config: Option<PathBuf>,
    #[command(flatten)]
    params: ParamArgs,
    #[command(flatten)]
    exec: ExecArgs,
    /// Compare each later survey with the first as well.
    #[arg(long)]
    baseline: bool,
    /// Give every pair its own m3c2.laz (and terrain positions), exactly compare's outputs.
    /// By default the time series (timeseries.parquet, timeseries.laz) holds every pair's
    /// distance at every core point and the pairs hold their events, meshes and summaries:
    /// about half the disk. Part of every pair's key: give it again with `--resume`.
    #[arg(long)]
    pair_clouds: bool,
    /// Continue an interrupted campaign, or one with surveys added, in DIR.
    #[arg(long, conflicts_with = "force")]
    resume: bool,
    /// Start over: throw away DIR's talus run and outputs (never files talus did not write).
    #[arg(long)]
    force: bool,
    /// Tile side (tests; default: planned from --memory).
    #[arg(long, hide = true)]
    tile_size: Option<f64>,
}

#[derive(Args)]
struct SynthArgs {
    /// hill | cube | spheres | cubes | cliff | deposit | hole | events | stable | large | dense | beach |
    /// vegetation | face | face-vertical | campaign
    scene: String,
    /// Directory to write the epochs (before.laz, after.laz; a campaign's survey_*.laz) and
    /// truth.json into.
    #[arg(long)]
    out: PathBuf,
    /// Points per epoch (default: per scene).
    #[arg(long)]
    points: Option<u64>,
    /// Surveys of `synth campaign` (3 to 401; default 5).
    #[arg(long)]
    epochs: Option<usize>,
    /// Seed of the random streams that draw the points (the planted changes do not depend on it).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Noise standard deviation along the surface normal, metres (default: per scene).
    #[arg(long)]
    noise: Option<f64>,
    /// Rotate the scene about the vertical axis (degrees).
    #[arg(long, default_value_t = 0.0)]
    rotate: f64,
    /// Density of epoch 2 relative to epoch 1.
    #[arg(long, default_value_t = 1.0)]
    density2: f64,
    /// Translate every epoch-2 point by DX,DY,DZ metres (a registration error, not a change).
    #[arg(long, value_name = "DX,DY,DZ", default_value = "0,0,0", allow_hyphen_values = true,
          value_parser = |s: &str| crate::synth::parse_shift(s).map_err(|e| e.to_string()))]
    shift: [f64; 3],
    /// Turn every epoch-2 point by RX,RY,RZ degrees about x, y and z through the scene's centre
    /// (a registration error, not a change).
    #[arg(long, value_name = "RX,RY,RZ", default_value = "0,0,0", allow_hyphen_values = true,
          value_parser = |s: &str| crate::synth::parse_turn(s).map_err(|e| e.to_string()))]
    turn: [f64; 3],
    /// A slow landslide under the whole scene: every epoch-2 point settles by up to this many
    /// metres, by amounts varying smoothly over the scene (not rigid, not a planted change).
    #[arg(
        long,
        value_name = "M",
        default_value_t = 0.0,
        allow_hyphen_values = true
    )]
    creep: f64,
    /// `synth campaign`: every survey after the first misregistered by a few centimetres and a
    /// fraction of a degree (recorded in truth.json), a registration error, not a change.
    #[arg(long)]
    misregister: bool,
    /// Write uncompressed LAS instead of LAZ.
    #[arg(long)]
    las: bool,
    /// `synth vegetation`: deliver the surveys classified (ground 2, grass 3, shrubs 4, tree 5)
    /// instead of unclassified (1). Every other scene's points are ground, class 2.
    #[arg(long)]
    classified: bool,
}

impl ParamArgs {
    fn user_params(&self) -> UserParams {
        UserParams {
            point_spacing: self.point_spacing,
            core_spacing: self.core_spacing,
            normal_radius: self.normal_radius,
            cyl_radius: self.cyl_radius,
            cyl_halflen: self.cyl_halflen,
            reg_error: self.reg_error,
            min_points: self.min_points,
            classes: self.classes.clone(),
            stable: self.stable.clone(),
            orientation: self.orientation.clone(),
            align: self.align.clone(),
            vegetation: self.vegetation.clone(),
            threshold: self.threshold,
            smooth_k: self.smooth_k,
            smooth_sigma: self.smooth_sigma,
            eps: self.eps,
            cluster_min_points: self.cluster_min_points,
            memory: self.memory.clone(),
            threads: self.threads,
            config: None,
        }
    }
}

fn run(cli: Cli) -> crate::Result<()> {
    // Commands that run units stop at a safe point on SIGINT/SIGTERM; the others (info, synth,
    // view) keep the default action: they end at once, having nothing to resume.
    if matches!(
        cli.command,
        Command::Compare(_) | Command::Campaign(_) | Command::Worker { .. } | Command::Demo { .. }
    ) {
        crate::interrupt::install();
    }
    match cli.command {
        Command::Compare(a) => {
            let opts = crate::commands::compare::CompareOptions {
                user: a.params.user_params(),
                before: a.before,
                after: a.after,
                out: a.out,
                config: a.config,
                core_points: a.core_points,
                resume: a.resume,
                force: a.force,
                before_mesh: a.before_mesh,
                after_mesh: a.after_mesh,
                tile_size: a.tile_size,
                m3c2_only: a.m3c2_only,
                keep_units: a.exec.keep_units,
                tiling_part: a.exec.tiling_part,
                executor: a.exec.executor()?,
            };
            if let Some(summary) = crate::commands::compare::compare(&opts)? {
                eprintln!("{}", summary.one_line());
            }
            Ok(())
        }
        Command::Campaign(a) => {
            let opts = crate::commands::campaign::CampaignOptions {
                user: a.params.user_params(),
                epochs: a.epochs,
                out: a.out,
                config: a.config,
                baseline: a.baseline,
                resume: a.resume,
                force: a.force,
                tile_size: a.tile_size,
                keep_units: a.exec.keep_units,
                tiling_part: a.exec.tiling_part,
                pair_clouds: a.pair_clouds,
                executor: a.exec.executor()?,
            };
            let Some(done) = crate::commands::campaign::campaign(&opts)? else {
                return Ok(());
            };
            eprintln!(
                "talus: campaign of {} surveys, {} pairs, {} tracks; outputs in {}",
                done.surveys,
                done.pairs,
                done.summary["tracks"],
                opts.out.display()
            );
            Ok(())
        }
        Command::Info { files, json } => crate::commands::info::print(&files, json),
        Command::Synth(s) => crate::commands::synth::synth(
            &s.scene,
            &s.out,
            s.epochs,
            s.misregister,
            crate::synth::SynthOptions {
                points: s.points,
                seed: s.seed,
                noise: s.noise,
                rotate_deg: s.rotate,
                density2: s.density2,
                shift_m: s.shift,
                turn_deg: s.turn,
                creep_m: s.creep,
                laz: !s.las,
                classified: s.classified,
            },
        ),
        Command::View { dir, port, bind } => crate::commands::view::command(&dir, bind, port),
        Command::Worker {
            dir,
            slots,
            threads,
        } => crate::commands::worker::worker(&dir, slots, threads),
        Command::Status { dir } => crate::commands::status::print(&dir),
        Command::SlurmTask {
            dir,
            submission,
            stage,
            task,
        } => crate::exec::slurm::task::run(&dir, submission, &stage, task),
        Command::PlanStats {
            dir,
            nodes,
            cores,
            scale,
        } => {
            print!(
                "{}",
                crate::exec::slurm::scaling::report(&dir, &nodes, cores, scale)?
            );
            Ok(())
        }
        Command::Demo { out, view } => crate::commands::demo::demo(&out, view),
    }
}

/// Parse the arguments, run the command, print its error; the process's exit code.
pub fn main() -> ExitCode {
    crate::progress::start_clock();
    crate::memory::limit_arenas();
    let cli = Cli::parse();
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(crate::Error::Interrupted) => {
            eprintln!("talus: interrupted; resume with --resume");
            ExitCode::from(130)
        }
        Err(e) => {
            eprintln!("talus: error: {e}");
            ExitCode::from(e.exit_code() as u8)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;

    /// Every option and argument of every (visible) subcommand says what it is: `--help` is where
    /// a newcomer learns the units and defaults.
    #[test]
    fn every_option_has_a_description() {
        fn walk(cmd: &clap::Command, path: &str, missing: &mut Vec<String>) {
            for a in cmd.get_arguments() {
                let id = a.get_id().as_str();
                if a.is_hide_set() || id == "help" || id == "version" {
                    continue;
                }
                let help = a.get_help().map(|h| h.to_string()).unwrap_or_default();
                if help.trim().is_empty() {
                    missing.push(format!("{path} {id}"));
                }
            }
            for sub in cmd.get_subcommands() {
                if sub.is_hide_set() || sub.get_name() == "help" {
                    continue;
                }
                walk(sub, &format!("{path} {}", sub.get_name()), missing);
            }
        }
        let cli = Cli::command();
        let mut missing = Vec::new();
        walk(&cli, "talus", &mut missing);
        assert!(
            missing.is_empty(),
            "options without a description: {missing:?}"
        );
        let compare = cli.find_subcommand("compare").unwrap();
        let memory = compare
            .get_arguments()
            .find(|a| a.get_id() == "memory")
            .and_then(|a| a.get_help())
            .map(|h| h.to_string())
            .unwrap_or_default();
        assert!(memory.contains("2 GiB"), "{memory}");
    }

    /// The help of a subcommand's argument or option `id`.
    fn help_of(sub: &str, id: &str) -> String {
        let cli = Cli::command();
        let cmd = cli.find_subcommand(sub).unwrap();
        let about = cmd.get_about().map(|a| a.to_string()).unwrap_or_default();
        let arg = cmd
            .get_arguments()
            .find(|a| a.get_id() == id)
            .and_then(|a| a.get_help())
            .map(|h| h.to_string())
            .unwrap_or_default();
        format!("{about}\n{arg}")
    }

    /// Issue 44, item 7: the help and README say what is true — every scene `synth` knows,
    /// every stage `slurm-task --stage` takes (the registry's and the publishing job), a worker
    /// serving a campaign too; README's synth classes, scenes, Slurm stages and worker.
    #[test]
    fn help_and_readme_name_what_there_is() {
        let readme = include_str!("../README.md");
        let scenes = help_of("synth", "scene");
        let synth_line = readme
            .lines()
            .find(|l| l.starts_with("talus synth SCENE"))
            .unwrap();
        for kind in crate::synth::SceneKind::ALL {
            let name = kind.name();
            let word = |t: &str| {
                t.split(|c: char| !(c.is_alphanumeric() || c == '-'))
                    .any(|w| w == name)
            };
            assert!(word(&scenes), "synth --help lacks {name}: {scenes}");
            assert!(word(synth_line), "README's synth line lacks {name}");
        }
        let stages = help_of("slurm-task", "stage");
        let arrays = readme
            .split("**How the plan maps onto job arrays.**")
            .nth(1)
            .and_then(|t| t.split("Every unit depends only").next())
            .unwrap();
        for kind in crate::units::stage::registry()
            .stages()
            .iter()
            .map(|s| s.kind())
        {
            assert!(stages.contains(kind), "slurm-task --stage lacks {kind}");
            assert!(
                arrays.contains(&format!("`{kind}`")),
                "README's arrays lack {kind}"
            );
        }
        assert!(stages.contains(crate::exec::slurm::PUBLISH));
        assert!(help_of("worker", "dir").contains("campaign"));
        assert!(
            readme.contains("beside its `compare`\n                              or `campaign`")
        );
        assert!(
            !readme.contains("all class 1"),
            "README: synth scenes are ground, class 2"
        );
    }
}
