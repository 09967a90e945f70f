//! `talus synth SCENE --out DIR`: a synthetic pair or campaign with exact ground truth.

use std::path::Path;

use crate::error::{Error, Result};
use crate::synth::campaign::{self, CampaignOptions};
use crate::synth::{SceneKind, SynthOptions};

/// `talus synth SCENE --out DIR` with the pair scenes' `opts` (SCENE `campaign`: `--epochs`
/// surveys, `--misregister`, no `--rotate`, `--density2`, `--shift`, `--turn` or `--creep`).
pub(crate) fn synth(
    scene: &str,
    out: &Path,
    epochs: Option<usize>,
    misregister: bool,
    opts: SynthOptions,
) -> Result<()> {
    if scene.trim().eq_ignore_ascii_case("campaign") {
        let plain = SynthOptions {
            points: opts.points,
            seed: opts.seed,
            noise: opts.noise,
            laz: opts.laz,
            ..SynthOptions::default()
        };
        if opts != plain {
            return Err(Error::Usage(
                "synth campaign: --rotate, --density2, --shift, --turn and --creep are for the \
                 pair scenes, --classified for the vegetation scene (a campaign's points are all \
                 ground, class 2)"
                    .into(),
            ));
        }
        let opts = CampaignOptions {
            epochs: epochs.unwrap_or(campaign::DEFAULT_EPOCHS),
            seed: opts.seed,
            points: opts.points,
            noise: opts.noise,
            laz: opts.laz,
            misregister,
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
    if epochs.is_some() || misregister {
        return Err(Error::Usage(
            "synth: --epochs and --misregister are for `synth campaign`".into(),
        ));
    }
    let kind: SceneKind = scene.parse()?;
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
