//! Errors an adapter or env reports. Each names what was wrong and what is valid.

/// An error from an adapter or one of its envs.
#[derive(Debug, thiserror::Error)]
pub enum EnvError {
    /// The adapter does not provide this env id.
    #[error("adapter `{adapter}` has no env `{env_id}`{}\nhint: `envhub adapters --all` lists adapters; this one provides: {}", did_you_mean(.closest), .known.join(", "))]
    UnknownEnv {
        /// The adapter asked.
        adapter: String,
        /// The env id asked for.
        env_id: String,
        /// The closest ids it does provide.
        closest: Vec<String>,
        /// Every id it provides.
        known: Vec<String>,
    },
    /// An `extra` (or `kwargs`) key the env does not take.
    #[error("unknown option `{key}` for `{env_id}`{}\nhint: valid options are: {}", did_you_mean(.closest), if .known.is_empty() { "(none)".to_string() } else { .known.join(", ") })]
    UnknownOption {
        /// The env id.
        env_id: String,
        /// The unknown key.
        key: String,
        /// The closest known keys.
        closest: Vec<String>,
        /// Every key the env takes.
        known: Vec<String>,
    },
    /// An option has a value of the wrong type or out of range.
    #[error("invalid option `{key}` for `{env_id}`: {reason}")]
    InvalidOption {
        /// The env id.
        env_id: String,
        /// The key.
        key: String,
        /// What is wrong and what is valid.
        reason: String,
    },
    /// A reset option the env does not understand or cannot apply.
    #[error("invalid reset option for `{env_id}`: {reason}")]
    InvalidReset {
        /// The env id.
        env_id: String,
        /// What is wrong.
        reason: String,
    },
    /// The adapter cannot run here: a dependency is missing.
    #[error("adapter `{adapter}` is unavailable: {reason}\nhint: {hint}")]
    Unavailable {
        /// The adapter.
        adapter: String,
        /// What is missing.
        reason: String,
        /// How to install it.
        hint: String,
    },
    /// A model or asset file could not be read or parsed.
    #[error("cannot load asset `{path}`: {reason}")]
    Asset {
        /// The file.
        path: String,
        /// The loader's own message.
        reason: String,
    },
    /// The requested render mode is not supported.
    #[error("render mode `{mode}` is not supported by `{env_id}`\nhint: supported: {}", .supported.join(", "))]
    RenderMode {
        /// The env id.
        env_id: String,
        /// The mode asked for.
        mode: String,
        /// Supported modes.
        supported: Vec<String>,
    },
    /// The simulator itself failed.
    #[error("simulator error in `{env_id}`: {reason}")]
    Simulator {
        /// The env id.
        env_id: String,
        /// The simulator's message.
        reason: String,
    },
}

/// `; did you mean `a` or `b`?` for a list of suggestions, or nothing when there are none.
pub fn did_you_mean(closest: &[String]) -> String {
    if closest.is_empty() {
        String::new()
    } else {
        format!(
            "; did you mean {}?",
            closest
                .iter()
                .map(|c| format!("`{c}`"))
                .collect::<Vec<_>>()
                .join(" or ")
        )
    }
}
