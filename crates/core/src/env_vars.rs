//! Every `ENVHUB_*` environment variable, in one place.

/// Path of the hub config file (default: `envhub.yaml` in the current directory, if present).
pub const ENVHUB_CONFIG: &str = "ENVHUB_CONFIG";

/// Registry files to use instead of the built-in catalog, separated by `:`
/// (`@default` names the built-in one, to combine it with others).
pub const ENVHUB_REGISTRY: &str = "ENVHUB_REGISTRY";

/// Log filter for the CLI and workers (as `RUST_LOG`, which is also honoured), e.g. `debug`.
pub const ENVHUB_LOG: &str = "ENVHUB_LOG";

/// Path of the `envhub-worker` binary (default: next to `envhub`, then `PATH`).
pub const ENVHUB_WORKER: &str = "ENVHUB_WORKER";

/// A folder holding `libmujoco.so.3.17.0` for the MuJoCo adapters, instead of the `mujoco`
/// package of the `ENVHUB_PYTHON` interpreter (read by `envhub-worker`).
pub const ENVHUB_MUJOCO_LIB: &str = "ENVHUB_MUJOCO_LIB";

/// iceoryx2 namespace (file prefix) for this process's sessions; tests set a unique one.
pub const ENVHUB_NAMESPACE: &str = "ENVHUB_NAMESPACE";

/// Control socket of a hub daemon (`envhub serve`) to use instead of the embedded hub.
pub const ENVHUB_HUB: &str = "ENVHUB_HUB";

/// `0` starts every worker of a suite's Python environment cold (a fresh interpreter that
/// imports the suite) instead of forking it from the environment's fork server, which the
/// embedded hub keeps per environment and adapter once a session has used it (default: on).
pub const ENVHUB_WARM_WORKERS: &str = "ENVHUB_WARM_WORKERS";

/// Python interpreter that runs Python-hosted adapters (`python -m envhub.worker`) and whose
/// packages the adapters use (Gymnasium's MuJoCo assets, the `mujoco` wheel's libmujoco), and
/// that the
/// parity tests compare against (default: the project's `.venv/bin/python`).
pub const ENVHUB_PYTHON: &str = "ENVHUB_PYTHON";

/// `1` lets the parity tests skip (with a note) when no Python with Gymnasium is available;
/// otherwise they fail, so a missing set-up cannot pass silently.
pub const ENVHUB_SKIP_PYTHON_TESTS: &str = "ENVHUB_SKIP_PYTHON_TESTS";

/// Set (non-empty) to make tests that need the compiled Python package (`make py-install`)
/// fail instead of skipping when it is missing; `make rust-test` and `make py-test` set it.
pub const ENVHUB_PY_REQUIRED: &str = "ENVHUB_PY_REQUIRED";

/// Set (non-empty) to make tests that need the MuJoCo adapter (a worker built with its
/// `mujoco` feature) fail instead of skipping when it is unavailable; `make rust-test` and
/// `make py-test` set it.
pub const ENVHUB_MUJOCO_REQUIRED: &str = "ENVHUB_MUJOCO_REQUIRED";

/// Set (non-empty) to make the LIBERO tests (`tests/python/worker/hosted/test_libero.py`) fail
/// instead of skipping when LIBERO or the `libero` adapter is unavailable; `make py-test` sets it
/// once `make libero` succeeded (LIBERO and its assets in `.venv-libero/`).
pub const ENVHUB_LIBERO_REQUIRED: &str = "ENVHUB_LIBERO_REQUIRED";

/// User adapter classes for Python workers, comma-separated import paths (`my_pkg.sim:MyAdapter`)
/// or `pickle:/path` (a class pickled by value, for one defined in a script's `__main__`), in
/// addition to the config's `adapters:`. `envhub.AdapterRegistry().register` sets it.
pub const ENVHUB_ADAPTERS: &str = "ENVHUB_ADAPTERS";

/// `1` lists the test adapters (`null`: `Null-v0`, an env that does no work and fails on
/// request) in the catalog, so registry entries can route to them; unset, they stay out of
/// users' sight, and only `envhub bench` and tests that name them directly use them.
pub const ENVHUB_TEST_ADAPTERS: &str = "ENVHUB_TEST_ADAPTERS";

/// Seconds a worker may take to create its envs and report ready before its session fails
/// (default 120: a suite such as LIBERO or robosuite imports and builds scenes for tens of
/// seconds, more on a loaded machine). A session's own `start_timeout` option wins.
pub const ENVHUB_START_TIMEOUT: &str = "ENVHUB_START_TIMEOUT";

/// Seconds that asking a worker what it hosts (`envhub-worker describe`,
/// `python -m envhub.worker describe`) may take before it is killed and reported as hung
/// (default 30): an adapter module that blocks at import cannot stall the hub.
pub const ENVHUB_DESCRIBE_TIMEOUT: &str = "ENVHUB_DESCRIBE_TIMEOUT";

/// Microseconds a hub's remote session thread looks for the next request (yielding the core)
/// before it sleeps (default 300; 0: always sleep). Spinning saves a wake-up per step on
/// machines with cores to spare.
pub const ENVHUB_BRIDGE_SPIN_US: &str = "ENVHUB_BRIDGE_SPIN_US";

/// The one cipher a client offers for its remote sessions, `aes-256-gcm` or
/// `chacha20-poly1305` (default: both, the faster on this CPU first; the hub picks). For
/// comparing them, or a CPU whose AES instructions are present but slow.
pub const ENVHUB_SESSION_CIPHER: &str = "ENVHUB_SESSION_CIPHER";

/// The folder of the Python environments built for suites (`python_envs:` in a registry),
/// one venv each (default: `$XDG_CACHE_HOME/envhub/pyenvs`, else `~/.cache/envhub/pyenvs`).
pub const ENVHUB_PYENV_DIR: &str = "ENVHUB_PYENV_DIR";

/// The folder where this user's hubs on loopback list their endpoints, and where the local
/// credential lives (default: `hubs/` of this user's private folder, see
/// [`crate::private_dir`]; tests: a folder of their own). Checked like that folder.
pub const ENVHUB_LOCAL_HUBS: &str = "ENVHUB_LOCAL_HUBS";

/// The `uv` executable that builds them (default: beside the hub's interpreter, then `PATH`).
pub const ENVHUB_UV: &str = "ENVHUB_UV";

/// `auto` (default): a session builds its entry's Python environment on first need;
/// `explicit`: only `envhub env sync` builds them, and a session whose environment is missing
/// fails with that hint. A hub serving remote clients builds for them only with
/// `envhub serve --allow-provision`, whatever this says.
pub const ENVHUB_PROVISION: &str = "ENVHUB_PROVISION";

/// The worker protocol version of the hub that starts a Python worker (set by the hub): a
/// worker of another version refuses to start, naming both (see `envhub_shm::WORKER_PROTOCOL`).
pub const ENVHUB_WORKER_PROTOCOL: &str = "ENVHUB_WORKER_PROTOCOL";

/// `1` lets envhub ask uv to install (download) a CPython version that a suite's Python
/// environment names and this machine lacks (`uv python install 3.X`); the config's
/// `python_install: true` does too. Unset, a missing version is an error naming that command.
pub const ENVHUB_PYTHON_INSTALL: &str = "ENVHUB_PYTHON_INSTALL";

/// Seconds a process waits for another one's build of the same Python environment before
/// giving up (default 900).
pub const ENVHUB_PYENV_WAIT: &str = "ENVHUB_PYENV_WAIT";

/// Set (non-empty) to make the tests that build Python environments (they need `uv`, a
/// second CPython and PyPI) fail instead of skipping when those are missing; `make
/// rust-test` and `make py-test` set it.
pub const ENVHUB_PYENV_REQUIRED: &str = "ENVHUB_PYENV_REQUIRED";

/// Set (non-empty) to make the suite tests (`tests/python/pyenv/test_suites.py`: Meta-World,
/// robosuite, dm_control, MyoSuite, each in its own Python environment) fail instead of
/// skipping when an environment cannot be built here; `make py-test` sets it.
pub const ENVHUB_SUITES_REQUIRED: &str = "ENVHUB_SUITES_REQUIRED";

/// Set (non-empty) to make the recorder's tests (`tests/python/recording/`) fail
/// instead of skipping when pyarrow, PyAV or LeRobot's loader is missing; `make py-test` sets
/// it.
pub const ENVHUB_RECORD_REQUIRED: &str = "ENVHUB_RECORD_REQUIRED";

/// The interpreter with LeRobot's dataset loader (`lerobot-dataset` and torch) that the
/// recorder's tests load datasets with (default `.venv-lerobot/bin/python`, `make lerobot`).
pub const ENVHUB_LEROBOT_PYTHON: &str = "ENVHUB_LEROBOT_PYTHON";
