//! A stage that *provides a survey's tiles*, added from outside the library the way a newcomer
//! adds one: one module (this file's [`Datum`]) and one registration (in `main`). The later
//! surveys are taken to be delivered in another vertical datum, [`OFFSET`] metres above the
//! first's (a fixed geoid separation): the stage writes their tiles lowered by it. It says so by
//! `Stage::TILES` alone, and every later unit — orientation, M3C2, stable ground, events,
//! volumes — reads its tiles instead of the tiling's: none of them, nor the planner, names it.
//! `tests/stage_extension.rs` runs it against plain talus.
//!
//! ```text
//! cargo run --release --example datum_stage -- compare before.laz after.laz --out DIR
//! ```

use talus::units::cleared::ClearedStage;
use talus::units::stage::{register, Line, Planner, Scope, Stage, TilesOf, Total};
use talus::units::tiling::{split, TilingMeta};
use talus::units::Ctx;

/// Metres the later surveys' heights lie above the first's datum.
const OFFSET: f64 = 0.5;

/// The later surveys' tiles in the first survey's vertical datum.
struct Datum;

impl Stage for Datum {
    const KIND: &'static str = "datum";
    const SCOPE: Scope = Scope::Survey;
    const VERSION: u32 = 1;
    const INTERMEDIATE: bool = true;
    const LINE: Line = Line {
        name: "datum",
        counts: "points",
        total: Total::Unknown,
    };
    type Meta = TilingMeta;
    const TILES: Option<TilesOf<TilingMeta>> = Some(|m| Some(m.clone()));

    /// One unit per later survey, after the units that tile it before (so that it runs after
    /// them and its key follows theirs).
    fn plan(p: &mut Planner) -> talus::Result<()> {
        for s in 1..p.plan.surveys.len() {
            let deps = p.survey_tiles(s)?;
            let label = p.plan.surveys[s].label.clone();
            p.add(
                talus::plan::Spec::survey(Self::KIND, s),
                &label,
                &[&format!("offset {OFFSET}")],
                deps,
            );
        }
        Ok(())
    }

    /// The survey tiled again from its files, every height lowered by [`OFFSET`] (on the
    /// file's own coordinate grid, as a decoder gives it).
    fn run(
        ctx: &Ctx,
        unit: usize,
        out: &mut talus::store::UnitWriter,
    ) -> talus::Result<TilingMeta> {
        let s = ctx.survey(unit)?;
        let quantum = ctx.quantum(s)?;
        let lower = move |pts: &mut [[f64; 3]]| {
            for p in pts.iter_mut() {
                let z = p[2] - OFFSET;
                p[2] = match quantum {
                    Some(t) => {
                        let [scale, offset] = t[2];
                        scale * ((z - offset) / scale).round() + offset
                    }
                    None => z,
                };
            }
        };
        split(ctx, s, Some(&lower), out)
    }
}

fn main() -> std::process::ExitCode {
    // The one registration: after the stages whose tiles it replaces.
    if let Err(e) = register::<Datum>(ClearedStage::KIND) {
        eprintln!("datum_stage: {e}");
        return std::process::ExitCode::from(1);
    }
    talus::cli::main()
}
