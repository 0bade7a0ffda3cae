//! The hub config file (`envhub.yaml`) and how the registry files are chosen.

use crate::env_vars::{ENVHUB_CONFIG, ENVHUB_REGISTRY};
use envhub_catalog::{DEFAULT_REGISTRY_NAME, Registry, RegistryError};
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// The file looked for in the current directory when `ENVHUB_CONFIG` is not set.
pub const CONFIG_FILE_NAME: &str = "envhub.yaml";

/// One path or several.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(untagged)]
pub enum OneOrMany {
    /// A single path.
    One(PathBuf),
    /// Several paths, combined in order.
    Many(Vec<PathBuf>),
}

/// Contents of `envhub.yaml`. Every field is optional; unknown fields are an error.
#[derive(Clone, Debug, Default, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Settings {
    /// Registry file(s) replacing the built-in catalog; relative paths are relative to the
    /// config file. List `@default` among them to keep the built-in entries.
    pub env_registry_path: Option<OneOrMany>,
    /// Interpreter for Python-hosted adapters (`ENVHUB_PYTHON` overrides it); relative paths
    /// are relative to the config file.
    pub python: Option<PathBuf>,
    /// Let envhub ask uv to install (download) a CPython version a suite's Python
    /// environment names and this machine lacks (`ENVHUB_PYTHON_INSTALL=1` does too).
    pub python_install: bool,
    /// User adapters hosted in Python workers, as import paths (`my_pkg.sim:MySimAdapter`):
    /// `envhub.EnvAdapter` subclasses; registry entries with their `framework` route to them.
    pub adapters: Vec<String>,
    /// How to reach other hubs over Zenoh (`connect`, `listen`, `config`, `multicast`,
    /// `lease_ms`, `known_hubs`); the command line and `ENVHUB_CONNECT` add to it.
    pub zenoh: envhub_net::NetConfig,
    /// Where the settings came from, for messages.
    #[serde(skip)]
    pub source: Option<PathBuf>,
}

/// An error reading the config file.
#[derive(Debug, thiserror::Error)]
pub enum SettingsError {
    /// The file could not be read.
    #[error("cannot read config `{path}`: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
    /// The file is not valid.
    #[error(
        "{path}: {message}\nhint: valid fields are `env_registry_path`, `python`, `python_install`, `adapters`, `zenoh` (with `connect`, `listen`, `config`, `multicast`, `lease_ms`, `known_hubs`)"
    )]
    Parse {
        /// The file.
        path: PathBuf,
        /// The parser's message, with line and column.
        message: String,
    },
}

impl Settings {
    /// Reads `path`.
    pub fn from_file(path: &Path) -> Result<Settings, SettingsError> {
        let text = std::fs::read_to_string(path).map_err(|source| SettingsError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        let mut settings: Settings = if text.trim().is_empty() {
            Settings::default()
        } else {
            serde_norway::from_str(&text).map_err(|e| SettingsError::Parse {
                path: path.to_path_buf(),
                message: e.to_string(),
            })?
        };
        let dir = path.parent().unwrap_or(Path::new("."));
        settings.env_registry_path = settings.env_registry_path.map(|p| {
            let anchor = |p: PathBuf| {
                if p.is_relative() && p != Path::new(DEFAULT_REGISTRY_NAME) {
                    dir.join(p)
                } else {
                    p
                }
            };
            match p {
                OneOrMany::One(p) => OneOrMany::One(anchor(p)),
                OneOrMany::Many(ps) => OneOrMany::Many(ps.into_iter().map(anchor).collect()),
            }
        });
        settings.python = settings.python.map(|p| {
            if p.components().count() > 1 && p.is_relative() {
                dir.join(p)
            } else {
                p
            }
        });
        if let Some(config) = &settings.zenoh.config
            && config.is_relative()
        {
            settings.zenoh.config = Some(dir.join(config));
        }
        settings.source = Some(path.to_path_buf());
        Ok(settings)
    }

    /// The explicit file, else `ENVHUB_CONFIG`, else `./envhub.yaml` if it exists, else defaults.
    pub fn discover(explicit: Option<&Path>) -> Result<Settings, SettingsError> {
        if let Some(path) = explicit {
            return Settings::from_file(path);
        }
        if let Some(path) = std::env::var_os(ENVHUB_CONFIG).filter(|p| !p.is_empty()) {
            return Settings::from_file(Path::new(&path));
        }
        let local = Path::new(CONFIG_FILE_NAME);
        if local.is_file() {
            return Settings::from_file(local);
        }
        Ok(Settings::default())
    }

    /// Registry files to load, by precedence: `explicit` (command line), then
    /// `ENVHUB_REGISTRY`, then `env_registry_path`, then the built-in catalog.
    pub fn registry_paths(&self, explicit: &[PathBuf]) -> Vec<PathBuf> {
        if !explicit.is_empty() {
            return explicit.to_vec();
        }
        if let Some(var) = std::env::var_os(ENVHUB_REGISTRY).filter(|v| !v.is_empty()) {
            return std::env::split_paths(&var).collect();
        }
        match &self.env_registry_path {
            Some(OneOrMany::One(p)) => vec![p.clone()],
            Some(OneOrMany::Many(ps)) => ps.clone(),
            None => vec![PathBuf::from(DEFAULT_REGISTRY_NAME)],
        }
    }

    /// Loads the registry these settings (and `explicit` files) select.
    pub fn registry(&self, explicit: &[PathBuf]) -> Result<Registry, RegistryError> {
        Registry::load(&self.registry_paths(explicit))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_zenoh_section_reaches_the_network_settings() {
        let dir = std::env::temp_dir().join(format!("envhub-settings-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("envhub.yaml");
        std::fs::write(
            &path,
            "zenoh:\n  connect: [tcp/10.0.0.5:7447]\n  config: zenoh.json5\n  multicast: false\n  lease_ms: 1500\n",
        )
        .unwrap();
        let settings = Settings::from_file(&path).unwrap();
        assert_eq!(
            settings.zenoh.connect,
            vec!["tcp/10.0.0.5:7447".to_string()]
        );
        assert_eq!(settings.zenoh.config, Some(dir.join("zenoh.json5")));
        assert_eq!(
            (settings.zenoh.multicast, settings.zenoh.lease_ms),
            (Some(false), Some(1500))
        );
        std::fs::write(&path, "zenoh:\n  conect: [tcp/10.0.0.5:7447]\n").unwrap();
        let e = Settings::from_file(&path).unwrap_err().to_string();
        assert!(e.contains("conect") && e.contains("connect"), "{e}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
