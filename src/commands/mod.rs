//! The commands, side by side: each plans a run or reads one, over the layers below (the
//! executors, the plan and its units, the store, the formats and the algorithms), which never
//! import a command.

pub mod campaign;
pub mod compare;
pub mod demo;
pub mod info;
pub mod removed;
pub mod run;
pub mod status;
pub mod synth;
pub mod view;
pub mod worker;
