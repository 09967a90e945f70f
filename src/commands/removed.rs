//! What `--vegetation remove` took out of each survey, said when a run ends: the points it
//! drops shift volumes and totals, and on ground without plants (a bare cliff) it still drops
//! some — the edges and creases of the terrain look scattered too — so the user is told how many
//! and by what rule, not left to find `vegetation_removed` in summary.json.

use crate::error::Result;
use crate::events::vegetation::SCALES;
use crate::plan::Plan;
use crate::store::Store;
use crate::units::cleared::{ClearedMeta, ClearedStage};
use crate::units::stage::{typed_meta, Stage};
use crate::units::unit_ref;

/// The note for a finished run of `plan` in `store`; None without `--vegetation remove`.
pub(crate) fn vegetation(store: &Store, plan: &Plan) -> Result<Option<String>> {
    let mut per_survey = Vec::new();
    for i in plan.of_kind(ClearedStage::KIND) {
        let u = &plan.units[i];
        let Some(record) = store.done(&unit_ref(plan, i)) else {
            continue;
        };
        let m: ClearedMeta = typed_meta(store, &unit_ref(plan, i), &record.meta)?;
        let compared = m.tiling.points + m.removed;
        let share = 100.0 * m.removed as f64 / compared.max(1) as f64;
        let label = u
            .spec
            .survey
            .map_or("?", |s| plan.surveys[s].label.as_str());
        per_survey.push(format!(
            "{} of {compared} points ({share:.1} %) of {label}",
            m.removed
        ));
    }
    if per_survey.is_empty() {
        return Ok(None);
    }
    let s = plan.params.point_spacing.value;
    Ok(Some(format!(
        "--vegetation remove left out {}: points whose neighbourhood is not planar in balls of \
         {} and {} point spacings ({:.3} and {:.3}), scattered through a volume as leaves and \
         twigs are (SPEC.md §4); where nothing grows they are edges and creases of the terrain. \
         M3C2, the events and their volumes are of the surveys without them (summary.json: \
         vegetation_removed)",
        per_survey.join(", "),
        SCALES[0],
        SCALES[1],
        SCALES[0] * s,
        SCALES[1] * s,
    )))
}
