//! `envhub eval`: a policy over a benchmark's protocol. The evaluation lives in the Python
//! package (`python -m envhub.evaluation`: benchmarks from the catalog, policies as Python
//! callables or policy servers, results, reports), which this runs with the hub's
//! interpreter, as `envhub record` runs the recorder: one implementation for the command line
//! and `envhub.eval` in Python.

use super::Outcome;
use anyhow::Context;
use std::ffi::OsString;
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

/// The hub's interpreter running `python -m envhub.evaluation ARGS`, with the command line's
/// registries and config file; its exit status is this command's.
pub(crate) fn run(
    registries: &[PathBuf],
    config: Option<&Path>,
    args: &Args,
) -> anyhow::Result<Outcome> {
    let (python, mut command) =
        super::record::python_module("envhub.evaluation", registries, config)?;
    let status = command.args(&args.args).status().with_context(|| {
        format!(
            "cannot run `{} -m envhub.evaluation`\nhint: the evaluation runs in the Python package: set ENVHUB_PYTHON to an interpreter with envhub installed",
            python.display()
        )
    })?;
    match status.code() {
        Some(0) => Ok(Outcome::Done),
        // The evaluation printed its own error (usage, a failed episode with --fail-fast).
        Some(code) => std::process::exit(code),
        None => anyhow::bail!("the evaluation was killed ({status})"),
    }
}
