//! What can go wrong with a registry file, and where in it: the error type of the catalog,
//! used by the registry and by its `python_envs:` section alike.

use envhub_core::did_you_mean;
use std::path::PathBuf;

/// The name under which the built-in catalog appears in lists of registry files.
pub const DEFAULT_REGISTRY_NAME: &str = "@default";

/// An error loading a registry file or looking something up in it.
#[derive(Debug, thiserror::Error, serde::Serialize, serde::Deserialize)]
#[serde(tag = "kind", content = "fields", rename_all = "snake_case")]
pub enum RegistryError {
    /// The file could not be read.
    #[error(
        "cannot read registry `{path}`: {source}\nhint: pass an existing YAML file, or `{DEFAULT_REGISTRY_NAME}` for the built-in catalog"
    )]
    Read {
        /// The file.
        path: PathBuf,
        /// The OS error.
        #[source]
        #[serde(with = "envhub_core::serde_text::io_text")]
        source: std::io::Error,
    },
    /// The YAML is malformed or does not fit the format.
    #[error("{path}:{line}:{column}: {message}\nhint: {hint}")]
    Parse {
        /// The file.
        path: String,
        /// 1-based line.
        line: usize,
        /// 1-based column.
        column: usize,
        /// What is wrong, with the field's path (`environments[3].task_tags`).
        message: String,
        /// How to fix it.
        hint: String,
    },
    /// A field has a value that is not allowed.
    #[error("{path}:{line}: `environments[{index}].{field}`: {message}")]
    Invalid {
        /// The file.
        path: String,
        /// 1-based line of the entry (0 if unknown).
        line: usize,
        /// Index of the entry.
        index: usize,
        /// The field.
        #[serde(deserialize_with = "envhub_core::serde_text::interned")]
        field: envhub_core::serde_text::StaticName,
        /// What is wrong.
        message: String,
    },
    /// Two entries of one file share an id.
    #[error(
        "{path}:{line}: duplicate id `{id}` (first defined at line {first_line})\nhint: ids must be unique within a file; to override an entry of another registry, put it in a later file"
    )]
    DuplicateId {
        /// The file.
        path: String,
        /// The id.
        id: String,
        /// Line of the second definition.
        line: usize,
        /// Line of the first definition.
        first_line: usize,
    },
    /// A `python_envs:` definition is invalid, or an entry or framework names an undefined one.
    #[error("{path}:{line}: {message}")]
    PythonEnv {
        /// The file.
        path: String,
        /// 1-based line (0 if unknown).
        line: usize,
        /// What is wrong, with the names that are defined and a hint.
        message: String,
    },
    /// A `benchmarks:` definition is not a mapping of fields.
    #[error("{path}:{line}: {message}")]
    Benchmark {
        /// The file.
        path: String,
        /// 1-based line (0 if unknown).
        line: usize,
        /// What is wrong.
        message: String,
    },
    /// The built-in catalog's model files have no folder of this user's to live in.
    #[error("the built-in catalog's model files cannot be written: {message}")]
    Assets {
        /// Which folder, what is wrong with it, and the fix.
        message: String,
    },
    /// No entry has this id.
    #[error("unknown environment id `{id}`{}\nhint: `envhub envs` lists every id", did_you_mean(.closest))]
    UnknownId {
        /// The id asked for.
        id: String,
        /// The closest ids that exist.
        closest: Vec<String>,
    },
}

/// 1-based lines where `id: <id>` is written (block style, with or without quotes).
pub(crate) fn id_lines(text: &str, id: &str) -> Vec<usize> {
    text.lines()
        .enumerate()
        .filter_map(|(i, line)| {
            let rest = line.trim_start().trim_start_matches("- ").trim_start();
            let value = rest.strip_prefix("id:")?;
            let value = value.split(" #").next().unwrap_or("").trim();
            let value = value.trim_matches(|c| c == '"' || c == '\'');
            (value == id).then_some(i + 1)
        })
        .collect()
}
