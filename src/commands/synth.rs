//! `talus synth SCENE --out DIR`: a synthetic pair or campaign with exact ground truth.

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
