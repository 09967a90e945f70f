//! Campaigns: many surveys of one site (SPEC.md §5). `epochs` dates and orders the surveys and
//! makes the pairs (`date` is the one date type of the program); `tracks` follows events
//! from pair to pair; [`powerlaw`] fits the magnitude–frequency law; [`report`] draws
//! report.html. The command is `crate::commands::campaign`.

pub(crate) mod date;
pub(crate) mod epochs;
pub(crate) mod tracks;

pub mod powerlaw;
pub mod report;
