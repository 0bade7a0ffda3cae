//! `Hub`: the registry, the adapter catalog and the routing, and what starts sessions.
//!
//! Embedded by default: the client process owns its workers. The `envhub serve` daemon
//! runs the same hub for many clients.

use crate::adapters::{self, AdapterInfo};
use crate::daemon_client::DaemonClient;
use crate::launcher::Launcher;
use crate::placement::Placement;
use crate::python_host::UserAdapters;
use crate::routing::{renders, route};
use crate::settings::Settings;
use envhub_catalog::Registry;
use envhub_core::{AutoresetMode, EnvConfig};
use envhub_net::{DISCOVERY, NetConfig, Network};
use envhub_protocol::HubError;
use envhub_protocol::Route;
use envhub_protocol::{HubInfo, keys};
use envhub_session::Env;
use envhub_session::LOCAL;
use envhub_session::SessionOptions;
use envhub_session::{StartPlan, VecEnv};
use std::sync::Arc;
use std::time::Duration;

/// The hub logic: resolves registry ids to adapters and starts worker sessions — here
/// (embedded), or through a hub daemon (`envhub serve`) when connected to one.
pub struct Hub {
    registry: Registry,
    options: SessionOptions,
    launcher: Launcher,
    /// How to reach other hubs (used only when a placement names some).
    net: NetConfig,
}

impl Hub {
    /// How this hub starts workers, as the engine takes it.
    fn launch(&self) -> Arc<dyn envhub_session::Launch> {
        Arc::new(self.launcher.clone())
    }

    /// A hub over `registry` with default session options.
    pub fn new(registry: Registry) -> Hub {
        Hub {
            registry,
            options: SessionOptions::default(),
            launcher: Launcher::Local,
            net: NetConfig::default().with_overrides(&[], &[], None),
        }
    }

    /// A hub that routes and starts workers through the daemon listening on `socket`.
    /// `registry` serves local lookups; routing uses the daemon's own registry.
    pub fn connect(socket: &std::path::Path, registry: Registry) -> Result<Hub, HubError> {
        Ok(Hub {
            registry,
            options: SessionOptions::default(),
            launcher: Launcher::Daemon(DaemonClient::connect(socket)?),
            net: NetConfig::default().with_overrides(&[], &[], None),
        })
    }

    /// The daemon this hub is connected to, if any.
    pub fn daemon(&self) -> Option<&DaemonClient> {
        match &self.launcher {
            Launcher::Daemon(d) => Some(d),
            Launcher::Local => None,
        }
    }

    /// A hub configured the usual way (`envhub.yaml`, `ENVHUB_*`; see [`Settings`]):
    /// connected to the daemon `ENVHUB_HUB` names, else embedded.
    pub fn from_env() -> Result<Hub, HubError> {
        let settings = Settings::discover(None).map_err(|e| HubError::InvalidConfig {
            what: "config file",
            reason: e.to_string(),
        })?;
        Hub::from_settings(&settings, &[])
    }

    /// A hub over `settings` and the registry files `explicit` (see [`Settings::registry`]).
    pub fn from_settings(
        settings: &Settings,
        explicit: &[std::path::PathBuf],
    ) -> Result<Hub, HubError> {
        let registry = settings.registry(explicit)?;
        if crate::python_host::configure(settings.python.clone(), settings.adapters.clone()) {
            crate::adapters::refresh_adapters();
        }
        let hub = match std::env::var_os(crate::env_vars::ENVHUB_HUB).filter(|s| !s.is_empty()) {
            Some(socket) => Hub::connect(std::path::Path::new(&socket), registry)?,
            None => Hub::new(registry),
        };
        Ok(hub.with_network(settings.zenoh.clone().with_overrides(&[], &[], None)))
    }

    /// Replaces how this hub reaches other hubs (see [`NetConfig::with_overrides`] for what
    /// the command line and environment add).
    pub fn with_network(mut self, net: NetConfig) -> Hub {
        self.net = net;
        self
    }

    /// How this hub reaches other hubs.
    pub fn network_config(&self) -> &NetConfig {
        &self.net
    }

    /// This process's presence on the hubs' network (opened on first use).
    pub fn network(&self) -> Result<Arc<Network>, HubError> {
        Network::get(&self.net)
    }

    /// The live hubs with their info (waits briefly for discovery on first use).
    pub fn hubs(&self) -> Result<Vec<HubInfo>, HubError> {
        self.network()?.hubs(DISCOVERY)
    }

    /// The registry of hub `name`.
    pub fn remote_registry(&self, name: &str) -> Result<Registry, HubError> {
        let network = self.network()?;
        network.wait_for(&[name.to_string()], DISCOVERY)?;
        let entries: Vec<crate::EnvEntry> =
            network.query(name, &keys::hub_catalog(name), None, Duration::from_secs(5))?;
        Ok(Registry::from_entries(entries, &format!("hub `{name}`")))
    }

    /// The adapters of hub `name`, with their availability there.
    pub fn remote_adapters(&self, name: &str) -> Result<Vec<AdapterInfo>, HubError> {
        let network = self.network()?;
        network.wait_for(&[name.to_string()], DISCOVERY)?;
        network.query(
            name,
            &keys::hub_adapters(name),
            None,
            Duration::from_secs(30),
        )
    }

    /// `num_envs` envs of registry entry `id`, placed as `placement` says: here, on remote
    /// hubs (each runs the id from its own catalog), or both. The same `VecEnv` either way.
    pub fn make_vec_on(
        &self,
        id: &str,
        num_envs: usize,
        config: &EnvConfig,
        placement: &Placement,
    ) -> Result<VecEnv, HubError> {
        if placement.is_local() {
            return self.make_vec(id, num_envs, config);
        }
        let network = self.network()?;
        let slices = crate::placement::resolve(placement, num_envs, Some(&network))?;
        let mut config = config.clone();
        config.num_envs = num_envs;
        let local_envs: usize = slices
            .iter()
            .filter(|s| s.place == LOCAL)
            .map(|s| s.num_envs)
            .sum();
        let route = if local_envs > 0 {
            let mut local = config.clone();
            local.num_envs = local_envs;
            Some(self.route(id, &local)?)
        } else {
            None
        };
        let options = self.options_for(route.as_ref());
        VecEnv::start_placed(
            StartPlan {
                id,
                route,
                config,
                slices,
                opener: Some(envhub_net::ZenohSlices::new(network)),
            },
            options,
            &self.launch(),
        )
    }

    /// The session options for a session on `route`: typed info columns only where a Python
    /// worker writes them. A Rust worker never does, and its slots stay the size of its
    /// results (more of them fit the pool).
    fn options_for(&self, route: Option<&Route>) -> SessionOptions {
        let mut options = self.options.clone();
        if options.info_row_bytes > 0 && !route.is_some_and(adapters::hosted_in_python) {
            options.info_row_bytes = 0;
        }
        options
    }

    /// Replaces the session options (timeouts, restart policy, namespace).
    pub fn with_options(mut self, options: SessionOptions) -> Hub {
        self.options = options;
        self
    }

    /// The session options.
    pub fn options(&self) -> &SessionOptions {
        &self.options
    }

    /// The registry.
    pub fn registry(&self) -> &Registry {
        &self.registry
    }

    /// Every adapter with its availability.
    pub fn adapters(&self) -> Result<Vec<AdapterInfo>, HubError> {
        match &self.launcher {
            Launcher::Daemon(d) => d.adapters(),
            Launcher::Local => Ok(adapters::adapters()?.to_vec()),
        }
    }

    /// Every adapter, with `user`'s beside this hub's own (a daemon answering a client).
    pub(crate) fn adapters_with(&self, user: &UserAdapters) -> Result<Vec<AdapterInfo>, HubError> {
        Ok(adapters::adapters_with(user)?.to_vec())
    }

    /// The adapter and config that would run `id` with `config`.
    pub fn route(&self, id: &str, config: &EnvConfig) -> Result<Route, HubError> {
        if let Launcher::Daemon(d) = &self.launcher {
            return d.route(id, config);
        }
        self.route_with(id, config, &UserAdapters::default())
    }

    /// [`Hub::route`] here, with `user`'s adapters beside this hub's own.
    pub(crate) fn route_with(
        &self,
        id: &str,
        config: &EnvConfig,
        user: &UserAdapters,
    ) -> Result<Route, HubError> {
        self.route_provisioning(id, config, user, crate::provision::automatic())
    }

    /// [`Hub::route_with`], building the entry's Python environment first if it needs one
    /// that is not ready and `may_build` (else that is an error saying how to build it).
    pub(crate) fn route_provisioning(
        &self,
        id: &str,
        config: &EnvConfig,
        user: &UserAdapters,
        may_build: bool,
    ) -> Result<Route, HubError> {
        let entry = self.registry.get(id)?;
        let hint = format!(
            "`envhub env sync {}` builds it (ENVHUB_PROVISION=explicit turned building on first need off)",
            crate::provision::env_of(&self.registry, entry).map_or("", |(name, _)| name)
        );
        if let Some(python) =
            crate::provision::worker_python(&self.registry, entry, may_build, &hint)?
        {
            // The environment's own packages decide which adapter runs the entry.
            let mut found = route(entry, &adapters::adapters_in(&python, user), config)
                .map_err(|e| in_python_env(e, &python.name))?;
            found.python = Some(python);
            return Ok(found);
        }
        // Native adapters first: when one runs the entry (and draws the render mode asked
        // for), Python is never started to ask.
        let native = adapters::native_adapters()?;
        if let Ok(found) = route(entry, &native, config)
            && native
                .iter()
                .any(|a| a.name == found.adapter && renders(a, found.config.render_mode.as_deref()))
        {
            return Ok(found);
        }
        route(entry, &adapters::adapters_with(user)?, config)
    }

    /// A batch of `num_envs` envs of registry entry `id`.
    pub fn make_vec(
        &self,
        id: &str,
        num_envs: usize,
        config: &EnvConfig,
    ) -> Result<VecEnv, HubError> {
        let mut config = config.clone();
        config.num_envs = num_envs;
        let route = self.route(id, &config)?;
        let options = self.options_for(Some(&route));
        VecEnv::start(id, route, options, &self.launch())
    }

    /// One env of registry entry `id`, in its own worker.
    pub fn make(&self, id: &str, config: &EnvConfig) -> Result<Env, HubError> {
        let mut config = config.clone();
        config.num_envs = 1;
        config.workers = Some(1);
        config.autoreset_mode = AutoresetMode::Disabled;
        let route = self.route(id, &config)?;
        let options = self.options_for(Some(&route));
        Ok(Env::new(VecEnv::start(id, route, options, &self.launch())?))
    }

    /// A batch of envs of an adapter's env id, bypassing the registry.
    pub fn make_vec_direct(
        &self,
        adapter: &str,
        env_id: &str,
        config: &EnvConfig,
    ) -> Result<VecEnv, HubError> {
        let route = Route {
            adapter: adapter.to_string(),
            env_id: env_id.to_string(),
            config: config.clone(),
            python: None,
        };
        let options = self.options_for(Some(&route));
        VecEnv::start(env_id, route, options, &self.launch())
    }
}

/// One env of registry entry `id` on the embedded hub, configured from the environment.
pub fn make(id: &str, config: &EnvConfig) -> Result<Env, HubError> {
    Hub::from_env()?.make(id, config)
}

/// `num_envs` envs of registry entry `id` on the embedded hub.
pub fn make_vec(id: &str, num_envs: usize, config: &EnvConfig) -> Result<VecEnv, HubError> {
    Hub::from_env()?.make_vec(id, num_envs, config)
}

/// `error` of routing an entry within the python env `name`, saying so: what the environment
/// lacks (its suite does not import, its worker does not start) is where to look.
fn in_python_env(error: HubError, name: &str) -> HubError {
    match error {
        HubError::Unavailable {
            adapter,
            reason,
            hint,
        } if !reason.contains(&format!("python env `{name}`")) => HubError::Unavailable {
            adapter,
            reason: format!("in python env `{name}`: {reason}"),
            hint,
        },
        HubError::NoAdapter {
            env_id,
            framework,
            detail,
            hint,
        } => HubError::NoAdapter {
            env_id,
            framework,
            detail: format!("{detail} (in python env `{name}`)"),
            hint,
        },
        other => other,
    }
}
