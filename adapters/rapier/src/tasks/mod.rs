//! The tasks, one file each, and the arm they share.

mod arm;
pub(crate) mod reach;
pub(crate) mod push;
pub(crate) mod ant;
pub(crate) mod rover;
mod terrain;
