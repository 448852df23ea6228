//! Modules of the `firstshot` binary only (`main.rs`), not of the library: the standard
//! streams, the outputs of a render, and the signals that stop one.

pub mod io;
pub mod outputs;
pub mod signals;
pub mod walkthrough;
