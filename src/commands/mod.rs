//! The commands, side by side: each plans a run or reads one, over the layers below (the
//! executors, the plan and its units, the store, the formats and the algorithms), which never
//! import a command.

pub mod campaign;
pub mod compare;
pub(crate) mod demo;
pub(crate) mod info;
pub(crate) mod removed;
pub(crate) mod run;
pub(crate) mod status;
pub(crate) mod synth;
pub mod view;
pub(crate) mod worker;
