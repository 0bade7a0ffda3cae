//! `envhub eval`: a policy over a benchmark's protocol. The evaluation lives in the Python
//! package (`python -m envhub.evaluation`: benchmarks from the catalog, policies as Python
//! callables or policy servers, results, reports), which this runs with the hub's
//! interpreter, as `envhub record` runs the recorder: one implementation for the command line
//! and `envhub.eval` in Python.
//!
//! The interpreter replaces this process (`exec`): a signal to `envhub eval` reaches the
//! evaluation itself, which stops its workers and its policy's process before it exits, and
//! no child is left running when this pid is gone.

use super::Outcome;
use std::ffi::OsString;
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};

#[derive(clap::Args, Debug)]
#[command(disable_help_flag = true)]
pub(crate) struct Args {
    /// The evaluation's own arguments (`envhub eval --help` lists them): a benchmark,
    /// `--policy MODULE:FUNCTION` or `--server URL`, `--out DIR`, ...
    #[arg(
        trailing_var_arg = true,
        allow_hyphen_values = true,
        value_name = "ARGS"
    )]
    args: Vec<OsString>,
}

/// Replaces this process with the hub's interpreter running `python -m envhub.evaluation
/// ARGS`, with the command line's registries and config file; returns only when the
/// interpreter cannot be run.
pub(crate) fn run(
    registries: &[PathBuf],
    config: Option<&Path>,
    args: &Args,
) -> anyhow::Result<Outcome> {
    let (python, mut command) =
        super::record::python_module("envhub.evaluation", registries, config)?;
    let error = command.args(&args.args).exec();
    anyhow::bail!(
        "cannot run `{} -m envhub.evaluation`: {error}\nhint: the evaluation runs in the Python package: set ENVHUB_PYTHON to an interpreter with envhub installed",
        python.display()
    )
}
