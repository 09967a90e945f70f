//! Campaigns: many surveys of one site (SPEC.md §5). [`epochs`] dates and orders the surveys and
//! makes the pairs ([`date`] is the one date type); [`tracks`] follows events from pair to pair.

pub mod command;
pub mod date;
pub mod epochs;
pub mod tracks;

pub mod powerlaw;
pub mod report;
