//! The campaign unit (SPEC.md §5): from every pair's outputs unit, the campaign's own files —
//! `campaign.csv` and `campaign.json` (the paper's Table 1, completed), `events.geojson` and
//! `events.csv` (every pair's events with their pair, dates and track), `timeseries.laz` and
//! `timeseries.parquet` (each core point's distance in every pair), `magnitude_frequency.csv`
//! with a power-law fit per gain and loss (in campaign.json), `report.html`, and
//! `summary.json`; and the list of files to publish: each pair's outputs under
//! `pairs/<before>_<after>/` and the campaign's own.

use rustc_hash::FxHashMap as HashMap;

use serde::{Deserialize, Serialize};
use serde_json::{json, Value};

use super::cores::ThinnedStage;
use super::outputs::tables::{
    EventFeature, EventProperties, Feature, FeatureCollection, PointGeometry, RegionFeature,
    RegionGeometry,
};
use super::outputs::view::ViewRange;
use super::outputs::{AlignmentSummary, OutputsStage, Publish, Summary};
use super::series::{SeriesReader, SeriesStage};
use super::stage::{Line, Planner, Publishes, Scope, Stage};
use super::{read_json, Ctx};
use crate::campaign::powerlaw::{self, PowerLawFit};
use crate::campaign::report::{self, EventRow, PairRow, Report};
use crate::campaign::tracks::{self, Placed};
use crate::error::{Error, Result};
use crate::events::Kind;
use crate::io::las_out::{self, CoordinateGrid, ExtraDim, ExtraType, ResultWriter};
use crate::io::parquet_out::{self, Column, ParquetWriter};
use crate::io::{self, Point3};
use crate::plan::Spec;
use crate::store::UnitWriter;

/// The campaign's marker (written last, removed first when published).
pub(crate) const MARKER: &str = "summary.json";

/// The names of the campaign files in DIR.
pub(crate) const FILES: &[&str] = &[
    "campaign.csv",
    "campaign.json",
    "events.geojson",
    "events.csv",
    "timeseries.laz",
    "timeseries.parquet",
    "magnitude_frequency.csv",
    "report.html",
    MARKER,
];

/// Is `name` (in a campaign's DIR) a talus output? The campaign files, and a pair's outputs
/// under `pairs/<label>/`.
pub(crate) fn is_output(name: &str) -> bool {
    if FILES.contains(&name) || name == "pairs" {
        return true;
    }
    match name.strip_prefix("pairs/") {
        Some(rest) => match rest.split_once('/') {
            None => true,
            Some((_, inner)) => super::outputs::is_output(inner) || inner == "meshes",
        },
        None => false,
    }
}

/// An event as the campaign reads it back from its pair's files (through the types the pair's
/// outputs wrote them with).
struct PairEvent {
    pair: usize,
    properties: EventProperties,
    centroid: Point3,
    region: Vec<Vec<Vec<Point3>>>,
}

/// The events of pair `pair` from its outputs unit `unit`.
fn pair_events(ctx: &Ctx, pair: usize, unit: usize) -> Result<Vec<PairEvent>> {
    let events: FeatureCollection<EventFeature> = read_json(ctx, unit, "events.geojson")?;
    let regions: FeatureCollection<RegionFeature> = read_json(ctx, unit, "event_regions.geojson")?;
    let mut by_id: HashMap<u32, Vec<Vec<Vec<Point3>>>> = HashMap::default();
    for f in regions.features {
        by_id.insert(
            f.properties.id,
            f.geometry.map(RegionGeometry::polygons).unwrap_or_default(),
        );
    }
    Ok(events
        .features
        .into_iter()
        .map(|f| {
            let PointGeometry::Point(centroid) = f.geometry;
            PairEvent {
                pair,
                centroid,
                region: by_id.remove(&f.properties.id).unwrap_or_default(),
                properties: f.properties,
            }
        })
        .collect())
}

/// An event of the campaign's events.geojson: its pair's properties, and where it is in the
/// campaign.
#[derive(Serialize)]
struct CampaignEvent<'a> {
    #[serde(flatten)]
    event: &'a EventProperties,
    pair: &'a str,
    before_date: String,
    after_date: String,
    /// None for an event in no track (vegetation, unless `--vegetation keep`): was 0, which a
    /// reader counted as one more track.
    track_id: Option<u32>,
}

/// A feature of the campaign's events.geojson.
#[derive(Serialize)]
struct CampaignFeature<'a> {
    #[serde(rename = "type")]
    kind: Feature,
    geometry: PointGeometry,
    properties: CampaignEvent<'a>,
}

/// A CSV cell of a property: as its JSON value, text quoted, null empty.
fn cell<T: Serialize>(v: &T) -> String {
    match serde_json::to_value(v) {
        Ok(Value::Null) | Err(_) => String::new(),
        Ok(Value::String(s)) => super::outputs::tables::csv_text(&s),
        Ok(v) => v.to_string(),
    }
}

/// One row of campaign.csv / campaign.json.
#[derive(Debug, Clone, Serialize)]
struct Row {
    #[serde(flatten)]
    row: PairRow,
    reg_error_m: f64,
    threshold_m: f64,
}

/// The campaign's outputs: table, tracks, time series, magnitude–frequency, report.
pub(crate) struct CampaignStage;

/// What the campaign unit records.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub(crate) struct CampaignMeta {
    /// The files to publish into DIR (the pairs' under `pairs/<label>/`).
    pub(crate) publish: Vec<Publish>,
    /// Events over all pairs.
    pub(crate) events: usize,
}

impl Stage for CampaignStage {
    const KIND: &'static str = "campaign";
    const SCOPE: Scope = Scope::Run;
    /// 3: the time series' distances as float32 (timeseries.laz, timeseries.parquet).
    const VERSION: u32 = 3;
    const LINE: Line = OutputsStage::LINE;
    type Meta = CampaignMeta;

    /// The units of its first and last surveys (their tiles, the last one's orientation field):
    /// the survey appended next is aligned onto the first and compared with the last. Not the
    /// per-tile samples of an orientation field (`units::field`): only its `orient` unit,
    /// kept, reads them.
    fn keeps(plan: &crate::plan::Plan) -> Vec<usize> {
        let ends = [Some(0), plan.surveys.len().checked_sub(1)];
        (0..plan.units.len())
            .filter(|&i| {
                let u = &plan.units[i].spec;
                u.pair.is_none()
                    && u.tile.is_none()
                    && u.survey.is_some()
                    && ends.contains(&u.survey)
            })
            .collect()
    }

    /// One per campaign, over every pair's outputs and column of the time series
    /// ([`super::series`]: not their M3C2 results, which are released after a run) and the
    /// campaign's core points.
    fn plan(p: &mut Planner) -> Result<()> {
        let Some(title) = p.campaign.clone() else {
            return Ok(());
        };
        let mut deps = vec![p.the(&Spec::survey(ThinnedStage::KIND, 0))?];
        deps.extend(p.plan.of_kind(OutputsStage::KIND).collect::<Vec<_>>());
        deps.extend(p.plan.of_kind(SeriesStage::KIND).collect::<Vec<_>>());
        let pairs = serde_json::to_string(&p.plan.pairs).unwrap_or_default();
        let version = env!("CARGO_PKG_VERSION");
        p.add(
            Spec::run(Self::KIND),
            "campaign",
            &[version, &pairs, &title],
            deps,
        );
        Ok(())
    }

    fn run(ctx: &Ctx, unit: usize, out: &mut UnitWriter) -> Result<CampaignMeta> {
        run(ctx, unit, out)
    }

    fn publishes() -> Option<Publishes<CampaignMeta>> {
        Some(Publishes {
            is_output,
            list: |m| &m.publish,
        })
    }
}

/// summary.json's `seconds`: the wall time of the run that computes the campaign, up to its
/// files (it was the sum of the pairs' stage times, which counts a survey's tiling once per pair
/// it is in and no time twice that ran at once). Measured by the command's own clock when the
/// unit runs in the process holding DIR's lock (a local run: from the command's start), else
/// from when the run wrote its plan (`.talus/plan.json`: a `talus worker` beside a run, a Slurm
/// task: from the submission).
fn wall_seconds(ctx: &Ctx) -> f64 {
    let here = ctx.store.lock_holder().is_some_and(|l| {
        l.owner.pid == std::process::id() && l.owner.host == crate::store::Owner::me().host
    });
    if here {
        return crate::progress::since_start();
    }
    std::fs::metadata(ctx.store.plan_path())
        .and_then(|m| m.modified())
        .ok()
        .and_then(|t| t.elapsed().ok())
        .map_or(0.0, |d| d.as_secs_f64())
}

/// Write the campaign's files into `out`.
fn run(ctx: &Ctx, unit: usize, out: &mut UnitWriter) -> Result<CampaignMeta> {
    let plan = ctx.plan;
    ctx.dep::<ThinnedStage>(unit)
        .ok_or_else(|| Error::Internal("a campaign without its core points".into()))?;
    let date = |s: usize| plan.surveys[s].date.clone().unwrap_or_default();
    let days = |s: usize| crate::campaign::epochs::Date::parse(&date(s)).map_or(0, |d| d.days());
    // Per pair: its summary and its events.
    let mut rows = Vec::new();
    // The widest of the pairs' colour ranges: the viewer's one scale for every pair.
    let mut range = [0.0f64, 0.0];
    let mut events: Vec<PairEvent> = Vec::new();
    let mut publish: Vec<Publish> = Vec::new();
    for (k, p) in plan.pairs.iter().enumerate() {
        let o = ctx.unit(&Spec::pair(OutputsStage::KIND, k))?;
        let summary: Summary = read_json(ctx, o, super::outputs::MARKER)?;
        let view: ViewRange = read_json(ctx, o, "view.json")?;
        range = [
            range[0].min(view.distance_range[0]),
            range[1].max(view.distance_range[1]),
        ];
        let mine = pair_events(ctx, k, o)?;
        let volumes: Vec<f64> = mine
            .iter()
            .filter_map(|e| e.properties.volume_uncertainty_m3)
            .collect();
        rows.push(Row {
            row: PairRow {
                label: p.label.clone(),
                before: plan.surveys[p.before].label.clone(),
                after: plan.surveys[p.after].label.clone(),
                before_date: date(p.before),
                after_date: date(p.after),
                days: days(p.after) - days(p.before),
                core_points: summary.core_points,
                significant_points: summary.significant_points,
                events: summary.events,
                gain_events: summary.gain_events,
                loss_events: summary.loss_events,
                gain_m3: summary.total_gain_m3,
                loss_m3: summary.total_loss_m3,
                net_m3: summary.total_gain_m3 + summary.total_loss_m3,
                mean_volume_uncertainty_m3: if volumes.is_empty() {
                    0.0
                } else {
                    volumes.iter().sum::<f64>() / volumes.len() as f64
                },
                seconds: summary.stages.iter().map(|s| s.seconds).sum(),
            },
            reg_error_m: summary.parameters.reg_error.value,
            threshold_m: summary.parameters.threshold.value,
        });
        events.extend(mine);
        // The pair's outputs go under pairs/<label>/.
        let list = ctx.meta::<OutputsStage>(o)?.publish;
        publish.extend(list.into_iter().map(|x| Publish {
            name: format!("pairs/{}/{}", p.label, x.name),
            ..x
        }));
    }
    // Vegetation events stay out of tracks, the fit and the report's sums (SPEC.md §4) unless
    // `--vegetation keep`; the pairs' totals already leave them out.
    let counts = |e: &PairEvent| plan.params.vegetation.value.counts(e.properties.vegetation);
    let gain = |e: &PairEvent| e.properties.kind == Kind::Gain;
    // Tracks over every pair's events that count (numbered from 1); the others are in none (0
    // here, no track_id in the files).
    let depth = plan.params.cyl_halflen.value;
    let counted: Vec<usize> = (0..events.len()).filter(|&i| counts(&events[i])).collect();
    let placed: Vec<Placed> = counted
        .iter()
        .map(|&i| {
            let e = &events[i];
            let obb = e.properties.obb;
            Placed {
                pair: e.pair,
                id: e.properties.id,
                gain: gain(e),
                centroid: e.centroid,
                depth: obb.half_extents[2] + depth,
                obb,
                region: e.region.clone(),
            }
        })
        .collect();
    let mut track = vec![0u32; events.len()];
    for (&i, t) in counted.iter().zip(tracks::tracks(&placed)) {
        track[i] = t;
    }
    // Magnitude–frequency over the consecutive pairs' significant events (a baseline pair
    // repeats them).
    let consecutive = |pair: usize| plan.pairs[pair].after == plan.pairs[pair].before + 1;
    let magnitudes = |kind: bool| -> Vec<f64> {
        events
            .iter()
            .filter(|e| {
                gain(e) == kind && consecutive(e.pair) && e.properties.significant && counts(e)
            })
            .filter_map(|e| e.properties.volume_m3)
            .map(f64::abs)
            .collect()
    };
    let (gains, losses) = (magnitudes(true), magnitudes(false));
    let (gain_fit, loss_fit) = (powerlaw::fit(&gains), powerlaw::fit(&losses));
    let crs_info = io::open(&plan.surveys[0].files[0].path)?.info().clone();
    // events.geojson / events.csv.
    write_events(out, &events, &track, plan, &date, &crs_info.crs.describe())?;
    // campaign.csv / campaign.json.
    // Each survey's alignment onto the first (none for the first, nor with `--align off`).
    let alignments = (0..plan.surveys.len())
        .map(|s| Ok(super::aligned::route(ctx, s)?.map(|r| AlignmentSummary::of(&r))))
        .collect::<Result<Vec<_>>>()?;
    write_table(
        out,
        &rows,
        [gain_fit.as_ref(), loss_fit.as_ref()],
        plan,
        &alignments,
        range,
    )?;
    // magnitude_frequency.csv.
    let mut mf = String::from("kind,volume_m3,events_at_least,exceedance\n");
    for (kind, values) in [("gain", &gains), ("loss", &losses)] {
        for (v, n, p) in powerlaw::exceedance(values) {
            mf.push_str(&format!("{kind},{v:.6},{n},{p:.6}\n"));
        }
    }
    super::write_bytes(out, "magnitude_frequency.csv", mf.as_bytes())?;
    // timeseries.laz.
    let series = write_timeseries(ctx, out, &crs_info)?;
    // report.html.
    let report = Report {
        title: format!(
            "talus campaign: {} surveys, {} to {}",
            plan.surveys.len(),
            date(0),
            date(plan.surveys.len() - 1)
        ),
        crs: crs_info.crs.describe(),
        pairs: rows.iter().map(|r| r.row.clone()).collect(),
        events: events
            .iter()
            .zip(&track)
            .map(|(e, &t)| EventRow {
                pair: e.pair,
                id: e.properties.id,
                kind: e.properties.kind.as_str().into(),
                volume_m3: e.properties.volume_m3,
                uncertainty_m3: e.properties.volume_uncertainty_m3,
                significant: e.properties.significant,
                complete: e.properties.complete,
                vegetation: !counts(e),
                track_id: t,
                centroid: e.centroid,
                region: e.region.clone(),
            })
            .collect(),
        gain_fit: gain_fit.clone(),
        loss_fit: loss_fit.clone(),
        generated_by: format!("talus {}", env!("CARGO_PKG_VERSION")),
    };
    super::write_bytes(out, "report.html", report::html(&report).as_bytes())?;
    // summary.json.
    let summary = json!({
        "tool": "talus",
        "version": env!("CARGO_PKG_VERSION"),
        "epochs": plan.surveys.iter().map(|s| json!({
            "label": s.label,
            "date": s.date,
            "survey": s.arg,
            "files": s.files.iter().map(|f| &f.path).collect::<Vec<_>>(),
            "points": s.points,
            "bounds": s.bounds,
            "crs": s.crs,
        })).collect::<Vec<_>>(),
        "parameters": plan.params,
        // Where the pairs' stable ground came from: `--stable` (the file) or their distances.
        "stable": match &plan.stable_areas {
            Some(a) => json!({
                "source": "user",
                "file": a.file.path,
                "polygons": a.areas.polygons.len(),
            }),
            None => json!({ "source": "automatic", "file": null }),
        },
        "spacing": plan.spacing,
        "pairs": rows.iter().map(|r| json!({
            "label": r.row.label,
            "reg_error_m": r.reg_error_m,
            "threshold_m": r.threshold_m,
            "events": r.row.events,
        })).collect::<Vec<_>>(),
        "tracks": track.iter().copied().max().unwrap_or(0),
        "tiles": plan.layout.len(),
        "core_points": series.points,
        "timeseries": series.summary(plan.pairs.len()),
        "seconds": wall_seconds(ctx),
    });
    let text = serde_json::to_vec_pretty(&summary).map_err(|e| Error::Internal(e.to_string()))?;
    super::write_bytes(out, MARKER, &text)?;
    publish.extend(FILES.iter().map(|&f| Publish::of(plan, unit, f, f.into())));
    (ctx.progress)(publish.len() as u64);
    Ok(CampaignMeta {
        publish,
        events: events.len(),
    })
}

fn write_events(
    out: &mut UnitWriter,
    events: &[PairEvent],
    track: &[u32],
    plan: &crate::plan::Plan,
    date: &dyn Fn(usize) -> String,
    crs: &str,
) -> Result<()> {
    let mut features = Vec::with_capacity(events.len());
    let mut csv = String::from(
        "pair,before_date,after_date,track_id,id,kind,volume_m3,volume_uncertainty_m3,\
         significant,gain_m3,loss_m3,coverage,region_area_m2,n_points,area_m2,mean_distance_m,\
         max_abs_distance_m,mean_lod95_m,complete,volume_note,vegetation_fraction,vegetation,x,y,z\n",
    );
    for (e, &t) in events.iter().zip(track) {
        let p = &plan.pairs[e.pair];
        let q = &e.properties;
        // Tracks are numbered from 1; 0 is no track.
        let t = (t > 0).then_some(t);
        features.push(CampaignFeature {
            kind: Feature::Feature,
            geometry: PointGeometry::Point(e.centroid),
            properties: CampaignEvent {
                event: q,
                pair: &p.label,
                before_date: date(p.before),
                after_date: date(p.after),
                track_id: t,
            },
        });
        let mut row = vec![
            p.label.clone(),
            date(p.before),
            date(p.after),
            cell(&t),
            cell(&q.id),
            cell(&q.kind),
            cell(&q.volume_m3),
            cell(&q.volume_uncertainty_m3),
            cell(&q.significant),
            cell(&q.gain_m3),
            cell(&q.loss_m3),
            cell(&q.coverage),
            cell(&q.region_area_m2),
            cell(&q.n_points),
            cell(&q.area_m2),
            cell(&q.mean_distance_m),
            cell(&q.max_abs_distance_m),
            cell(&q.mean_lod95_m),
            cell(&q.complete),
            cell(&q.volume_note),
            cell(&q.vegetation_fraction),
            cell(&q.vegetation),
        ];
        row.extend(e.centroid.iter().map(|v| format!("{v:.4}")));
        csv.push_str(&row.join(","));
        csv.push('\n');
    }
    let fc = FeatureCollection::new(crs.to_string(), features).to_value()?;
    let text = serde_json::to_vec_pretty(&fc).map_err(|e| Error::Internal(e.to_string()))?;
    super::write_bytes(out, "events.geojson", &text)?;
    super::write_bytes(out, "events.csv", csv.as_bytes())
}

/// campaign.csv and campaign.json: the pairs' rows, the power-law fits (gain, loss), the epochs
/// with their alignments, and the colour range every pair is drawn on.
fn write_table(
    out: &mut UnitWriter,
    rows: &[Row],
    [gain, loss]: [Option<&PowerLawFit>; 2],
    plan: &crate::plan::Plan,
    alignments: &[Option<AlignmentSummary>],
    distance_range: [f64; 2],
) -> Result<()> {
    let mut sorted: Vec<&Row> = rows.iter().collect();
    sorted.sort_by(|a, b| {
        (&a.row.after_date, &a.row.before_date).cmp(&(&b.row.after_date, &b.row.before_date))
    });
    let mut csv = String::from(
        "before,after,before_date,after_date,days,core_points,significant_points,events,\
         gain_events,loss_events,gain_m3,loss_m3,net_m3,mean_volume_uncertainty_m3,seconds,\
         reg_error_m,threshold_m\n",
    );
    for r in &sorted {
        let x = &r.row;
        csv.push_str(&format!(
            "{},{},{},{},{},{},{},{},{},{},{:.3},{:.3},{:.3},{:.3},{:.2},{:.4},{:.4}\n",
            x.before,
            x.after,
            x.before_date,
            x.after_date,
            x.days,
            x.core_points,
            x.significant_points,
            x.events,
            x.gain_events,
            x.loss_events,
            x.gain_m3,
            x.loss_m3,
            x.net_m3,
            x.mean_volume_uncertainty_m3,
            x.seconds,
            r.reg_error_m,
            r.threshold_m,
        ));
    }
    super::write_bytes(out, "campaign.csv", csv.as_bytes())?;
    let table = json!({
        "pairs": sorted,
        "power_law": {
            "method": "maximum likelihood, x_min by the Kolmogorov–Smirnov distance (Clauset, Shalizi & Newman 2009), over the significant events of consecutive pairs",
            "gain": gain,
            "loss": loss,
        },
        "epochs": plan.surveys.iter().zip(alignments).map(|(s, a)| json!({
            "label": s.label,
            "date": s.date,
            "alignment": a,
        })).collect::<Vec<_>>(),
        // One colour scale for every pair (the viewer's), so that pairs compare by eye: the
        // widest of the pairs' ranges (view.json: 2nd and 98th percentiles of the distances).
        "distance_range": distance_range,
    });
    let text = serde_json::to_vec_pretty(&table).map_err(|e| Error::Internal(e.to_string()))?;
    super::write_bytes(out, "campaign.json", &text)
}

/// The time series as written: its core points, and whether timeseries.laz holds the pairs'
/// distances.
struct Timeseries {
    points: u64,
    laz_distances: bool,
}

impl Timeseries {
    /// summary.json's `timeseries`: what each file holds.
    fn summary(&self, pairs: usize) -> Value {
        let laz = if self.laz_distances {
            "the core points with one extra-bytes dimension per pair, d_<before>_<after>"
                .to_string()
        } else {
            format!(
                "the core points only: the descriptors of {pairs} pairs' dimensions (192 bytes \
                 each) exceed what a LAS VLR holds ({} pairs at most), and LAS readers do not \
                 read them from an EVLR; the distances are in timeseries.parquet",
                las_out::MAX_VLR_EXTRA_DIMS
            )
        };
        json!({
            "laz": laz,
            "laz_distances": self.laz_distances,
            "parquet": "x, y, z (the core points as timeseries.laz stores them) and one column \
                        per pair, d_<before>_<after>, null where no distance was computed",
        })
    }
}

/// timeseries.laz and timeseries.parquet: the campaign's core points (every pair has the same,
/// in the same key order) with one column per pair, `d_<before>_<after>`, the M3C2 distance (NaN
/// in the LAS, null in the Parquet, where not computed). timeseries.laz holds the pairs'
/// dimensions while their descriptors fit the Extra Bytes VLR (`las_out::MAX_VLR_EXTRA_DIMS`
/// pairs), the core points alone past that (still a `--core-points` file).
fn write_timeseries(ctx: &Ctx, out: &mut UnitWriter, crs: &io::CloudInfo) -> Result<Timeseries> {
    let plan = ctx.plan;
    let names: Vec<String> = plan
        .pairs
        .iter()
        .map(|p| {
            format!(
                "d_{}_{}",
                plan.surveys[p.before].label, plan.surveys[p.after].label
            )
        })
        .collect();
    let laz_distances = names.len() <= las_out::MAX_VLR_EXTRA_DIMS;
    let dims: Vec<ExtraDim> = if laz_distances {
        names
            .iter()
            .map(|n| ExtraDim {
                name: n.clone().into(),
                ty: ExtraType::F32,
                description: "M3C2 distance of the pair",
            })
            .collect()
    } else {
        Vec::new()
    };
    let extent = &plan.layout.extent;
    let scales: Vec<[f64; 3]> = plan.surveys[0].scale.into_iter().collect();
    let grid = CoordinateGrid::for_extent(extent.min, extent.max, &scales);
    let path = out.path("timeseries.laz")?;
    // Every pair's column (`units::series`): every pair has the campaign's core points in key
    // order; counts and key hashes check it. The first pair's rows hold x, y, z beside its
    // distance.
    let series: Vec<usize> = (0..plan.pairs.len())
        .map(|k| ctx.unit(&Spec::pair(SeriesStage::KIND, k)))
        .collect::<Result<_>>()?;
    let metas = series
        .iter()
        .map(|&u| ctx.meta::<SeriesStage>(u))
        .collect::<Result<Vec<_>>>()?;
    let first = &metas[0];
    for (k, m) in metas.iter().enumerate().skip(1) {
        if (m.core_points, &m.keys) != (first.core_points, &first.keys) {
            return Err(Error::Internal(format!(
                "pair {k}'s core points differ from pair 0's ({} against {})",
                m.core_points, first.core_points
            )));
        }
    }
    let n = first.core_points;
    let mut w = ResultWriter::create_on_grid(&path, &crs.crs, &dims, grid, Some(n))?;
    // One pass over the columns writes the LAS and the first pair's columns (x, y, z as the LAS
    // stores them, its distance) into scratch files; then the Parquet is written from those and
    // the other pairs' columns, a column of a row group at a time.
    let parquet_columns = plan.pairs.len() + 3;
    let _held = ctx.reserve(
        (parquet_columns * super::scratch::BUFFER) as u64
            + crate::memory::IO_HEADROOM
            + parquet_out::memory_need(parquet_columns, n),
        "the time series (every pair's column, then the Parquet a column at a time)",
    )?;
    let mut first_rows = SeriesReader::open(ctx, series[0], 4)?;
    let mut readers = if laz_distances {
        series[1..]
            .iter()
            .map(|&u| SeriesReader::open(ctx, u, 1))
            .collect::<Result<Vec<_>>>()?
    } else {
        Vec::new()
    };
    let mut first_columns = ["x", "y", "z", "d"]
        .iter()
        .map(|c| super::scratch::RowsWriter::create(out, &format!("timeseries_{c}.tmp"), 1))
        .collect::<Result<Vec<_>>>()?;
    let mut values = vec![f64::NAN; dims.len()];
    for _ in 0..n {
        let row = first_rows.next_row()?;
        let (xyz, d) = ([row[0], row[1], row[2]], row[3]);
        let stored = grid.decoded(xyz).ok_or_else(|| {
            Error::Internal(format!(
                "core point {xyz:?} off the time series' grid {grid:?}"
            ))
        })?;
        for (c, v) in first_columns
            .iter_mut()
            .zip([stored[0], stored[1], stored[2], d])
        {
            c.push(&[v])?;
        }
        if laz_distances {
            values[0] = d;
            for (k, rd) in readers.iter_mut().enumerate() {
                values[k + 1] = rd.next_row()?[0];
            }
        }
        w.write(xyz, &values)?;
    }
    drop((first_rows, readers));
    w.finish()?;
    out.add_file("timeseries.laz")?;
    let columns: Vec<super::scratch::Rows> = first_columns
        .into_iter()
        .map(|c| c.finish())
        .collect::<Result<Vec<_>>>()?;
    let mut sources: Vec<Box<dyn super::series::Values>> = Vec::new();
    for c in &columns {
        sources.push(Box::new(c.reader()?));
    }
    for &u in &series[1..] {
        sources.push(Box::new(SeriesReader::open(ctx, u, 1)?));
    }
    write_parquet(ctx, out, crs, &names, &mut sources, n)?;
    drop(sources);
    for c in columns {
        c.remove()?;
    }
    Ok(Timeseries {
        points: n,
        laz_distances,
    })
}

/// timeseries.parquet from the time series' scratch columns (x, y, z, then each pair's
/// distance), `rows` rows; its key-value metadata: talus's version, the CRS (the first survey's
/// WKT and EPSG code, when it has them) and the pairs (column, labels and dates).
fn write_parquet(
    ctx: &Ctx,
    out: &mut UnitWriter,
    crs: &io::CloudInfo,
    names: &[String],
    sources: &mut [Box<dyn super::series::Values>],
    rows: u64,
) -> Result<()> {
    let plan = ctx.plan;
    let schema: Vec<Column> = ["x", "y", "z"]
        .iter()
        .map(|c| Column::required(c))
        .chain(names.iter().map(|n| Column::nullable(n).single()))
        .collect();
    let date = |s: usize| plan.surveys[s].date.clone();
    let pairs: Vec<Value> = plan
        .pairs
        .iter()
        .zip(names)
        .map(|(p, n)| {
            json!({
                "column": n,
                "before": plan.surveys[p.before].label,
                "after": plan.surveys[p.after].label,
                "before_date": date(p.before),
                "after_date": date(p.after),
            })
        })
        .collect();
    let mut metadata =
        vec![
        ("talus:version".to_string(), env!("CARGO_PKG_VERSION").to_string()),
        (
            "talus:description".to_string(),
            "x, y, z: the campaign's core points (in the CRS's units), as timeseries.laz stores \
             them; d_<before>_<after>: the pair's M3C2 distance at the core point (metres, \
             float32 as m3c2.laz's m3c2_distance), null where none was computed"
                .to_string(),
        ),
    ];
    if let Some(w) = &crs.crs.wkt {
        metadata.push(("talus:crs_wkt".into(), w.clone()));
    }
    if let Some(e) = crs.crs.epsg_code() {
        metadata.push(("talus:crs_epsg".into(), e.to_string()));
    }
    metadata.push((
        "talus:pairs".into(),
        serde_json::to_string(&pairs).map_err(|e| Error::Internal(e.to_string()))?,
    ));
    let path = out.path("timeseries.parquet")?;
    let mut pw = ParquetWriter::create(&path, &schema, &metadata)?;
    let per_group = parquet_out::rows_per_group(schema.len()) as u64;
    let mut left = rows;
    while left > 0 {
        let n = left.min(per_group);
        pw.write_group(n as usize, &mut |c, values| sources[c].next_values(values))?;
        left -= n;
    }
    pw.finish()?;
    out.add_file("timeseries.parquet")
}
