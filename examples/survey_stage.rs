//! A stage added from outside the library, the way a newcomer adds one: one module (this file's
//! [`SurveyHeights`]: a type implementing `Stage`) and one registration (in `main`, before the
//! command line runs). It is a per-survey statistic — each survey's point count and its height
//! range and mean, from the survey's tiles — planned after the tilings, run by this process's
//! executor, by `survey_stage worker DIR`, and as a job array of its own on Slurm, because every
//! driver reads the stages from the registry. `tests/stage_extension.rs` runs it all three ways.
//!
//! ```text
//! cargo run --release --example survey_stage -- compare before.laz after.laz --out DIR
//! cat DIR/.talus/units/survey_heights/*/heights.json
//! ```

use serde::{Deserialize, Serialize};

use talus::plan::Spec;
use talus::store::UnitWriter;
use talus::units::stage::{register, Line, Planner, Scope, Stage, Total};
use talus::units::tiling::TilingStage;
use talus::units::{read_tile, write_json, Ctx};

/// Each survey's count and heights.
struct SurveyHeights;

/// What a `survey_heights` unit records, and writes as `heights.json`.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct Heights {
    survey: String,
    points: u64,
    min_z: f64,
    max_z: f64,
    mean_z: f64,
}

impl Stage for SurveyHeights {
    const KIND: &'static str = "survey_heights";
    const SCOPE: Scope = Scope::Survey;
    const VERSION: u32 = 1;
    const LINE: Line = Line {
        name: "survey heights",
        counts: "points",
        total: Total::SurveyPoints,
    };
    type Meta = Heights;

    /// One unit per survey, reading that survey's tiling; its key needs nothing more (the
    /// tiling's key is a dependency's, so a changed survey changes it).
    fn plan(p: &mut Planner) -> talus::Result<()> {
        for s in 0..p.plan.surveys.len() {
            // Its tiling unit, or its parts (a large survey is tiled by several units).
            let tiling = p.plan.survey_units(TilingStage::KIND, s);
            if tiling.is_empty() {
                continue;
            }
            let label = p.plan.surveys[s].label.clone();
            p.add(Spec::survey(Self::KIND, s), &label, &[], tiling);
        }
        Ok(())
    }

    /// The survey's tiles one at a time, each point counted by the tile that owns it; summed in
    /// grid order, so every process gets the same bytes.
    fn run(ctx: &Ctx, unit: usize, out: &mut UnitWriter) -> talus::Result<Heights> {
        let survey = ctx.survey(unit)?;
        // The survey as delivered: its own tiling (not an aligned one).
        let tiling = ctx.own_tiling(survey)?;
        let (mut n, mut sum) = (0u64, 0.0f64);
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for id in ctx.plan.layout.grid()?.tiles() {
            let t = read_tile(ctx, &tiling, id)?;
            for i in (0..t.len()).filter(|&i| t.owned[i]) {
                n += 1;
                sum += t.z[i];
                lo = lo.min(t.z[i]);
                hi = hi.max(t.z[i]);
            }
            (ctx.progress)(t.owned.iter().filter(|&&o| o).count() as u64);
        }
        let h = Heights {
            survey: ctx.plan.surveys[survey].label.clone(),
            points: n,
            min_z: lo,
            max_z: hi,
            mean_z: sum / n.max(1) as f64,
        };
        write_json(out, "heights.json", &h)?;
        Ok(h)
    }
}

fn main() -> std::process::ExitCode {
    // The one registration: after the tilings it reads.
    if let Err(e) = register::<SurveyHeights>(TilingStage::KIND) {
        eprintln!("survey_stage: {e}");
        return std::process::ExitCode::from(1);
    }
    talus::cli::main()
}
