//! (local stand-in for the report helper's module; replaced at merge)
use super::powerlaw::PowerLawFit;
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct PairRow {
    pub label: String,
    pub before: String,
    pub after: String,
    pub before_date: String,
    pub after_date: String,
    pub days: i64,
    pub core_points: u64,
    pub significant_points: u64,
    pub events: usize,
    pub gain_events: usize,
    pub loss_events: usize,
    pub gain_m3: f64,
    pub loss_m3: f64,
    pub net_m3: f64,
    pub mean_volume_uncertainty_m3: f64,
    pub seconds: f64,
}
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct EventRow {
    pub pair: usize,
    pub id: u32,
    pub kind: String,
    pub volume_m3: Option<f64>,
    pub uncertainty_m3: Option<f64>,
    pub significant: bool,
    pub track_id: u32,
    pub centroid: [f64; 3],
    pub region: Vec<Vec<Vec<[f64; 3]>>>,
}
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct Report {
    pub title: String,
    pub crs: String,
    pub pairs: Vec<PairRow>,
    pub events: Vec<EventRow>,
    pub gain_fit: Option<PowerLawFit>,
    pub loss_fit: Option<PowerLawFit>,
    pub generated_by: String,
}
pub fn html(r: &Report) -> String {
    format!("<html><title>{}</title></html>", r.title)
}
