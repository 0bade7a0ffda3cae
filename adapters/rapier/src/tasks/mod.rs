//! The tasks, one file each, and the arm they share.

pub(crate) mod ant;
mod arm;
pub(crate) mod push;
pub(crate) mod reach;
pub(crate) mod rover;
mod terrain;
