//! What envhub writes on its own (the built-in model files, this machine's hub entries and
//! the local credential, the daemon's socket) against another user of the machine, as that
//! user would try it: uid 65534 makes every name envhub once used in the shared temporary
//! folder first, with links at the temporary names beside them pointing at a file of the
//! victim's; then the victim (root) lists the catalog, runs a session on the built-in
//! `custom-mjcf-planar-walker` model and starts a hub. Nothing of the victim's changes and
//! nothing of it lands in the shared folder. Where the victim's own private folder is one the
//! other user made first (or a link it planted), the run fails naming that folder.
//!
//! Needs root, to run a process as another uid; skipped with the reason otherwise, unless
//! `ENVHUB_OTHER_USER_REQUIRED` is set (then a skip is a failure). CI runs as root.

use envhub_e2e::binary;
use std::io::BufRead;
use std::os::unix::fs::{MetadataExt, PermissionsExt};
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

/// Set (non-empty) to turn a skip into a failure, where the tests must run.
const REQUIRED: &str = "ENVHUB_OTHER_USER_REQUIRED";

const NOBODY: u32 = 65534;

/// The built-in model, as the binary carries it.
const PLANAR_WALKER: &str = include_str!("../../configs/assets/planar_walker.xml");

/// What the victim must never lose.
const PRECIOUS: &str = "root's own file, which no run of envhub may change\n";

fn supported(test: &str) -> bool {
    // SAFETY: geteuid has no preconditions.
    if unsafe { libc::geteuid() } == 0 {
        return true;
    }
    assert!(
        std::env::var_os(REQUIRED).is_none_or(|v| v.is_empty()),
        "{test}: the other-user tests are required ({REQUIRED}) but this process is not root"
    );
    eprintln!("skipped {test}: running a process as another uid needs root");
    false
}

/// A scene: `shared` (mode 1777, as `/tmp`), the victim's `home` (0700) and its `precious`
/// file (0644), all under one folder removed when dropped.
struct Scene {
    base: PathBuf,
    shared: PathBuf,
    home: PathBuf,
    precious: PathBuf,
}

impl Drop for Scene {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.base);
    }
}

impl Scene {
    fn new(tag: &str) -> Scene {
        let base =
            std::env::temp_dir().join(format!("e2e-local-files-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&base);
        std::fs::create_dir_all(&base).unwrap();
        std::fs::set_permissions(&base, std::fs::Permissions::from_mode(0o755)).unwrap();
        let (shared, home) = (base.join("tmp"), base.join("home"));
        std::fs::create_dir(&shared).unwrap();
        std::fs::set_permissions(&shared, std::fs::Permissions::from_mode(0o1777)).unwrap();
        std::fs::create_dir(&home).unwrap();
        std::fs::set_permissions(&home, std::fs::Permissions::from_mode(0o700)).unwrap();
        let precious = base.join("precious");
        std::fs::write(&precious, PRECIOUS).unwrap();
        std::fs::set_permissions(&precious, std::fs::Permissions::from_mode(0o644)).unwrap();
        Scene {
            base,
            shared,
            home,
            precious,
        }
    }

    /// Runs `script` (`sh -c`) as uid 65534, with `$S` the shared folder and `$T` the
    /// victim's file.
    fn as_other_user(&self, script: &str) {
        let out = Command::new("sh")
            .args(["-c", script])
            .env("S", &self.shared)
            .env("T", &self.precious)
            .uid(NOBODY)
            .gid(NOBODY)
            .current_dir("/")
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "the other user's set-up failed: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }

    /// `envhub args` as the victim: its home, the shared folder as its temporary folder, no
    /// runtime folder unless `runtime` names one.
    fn victim(&self, args: &[&str], runtime: Option<&Path>) -> Command {
        let mut cmd = Command::new(binary("envhub"));
        cmd.args(args)
            .env("HOME", &self.home)
            .env("TMPDIR", &self.shared)
            .env_remove("XDG_RUNTIME_DIR")
            .env_remove("XDG_CACHE_HOME")
            .env_remove(envhub_hub::local::ENVHUB_LOCAL_HUBS)
            .env_remove(envhub_hub::env_vars::ENVHUB_HUB)
            .env_remove(envhub_hub::ENVHUB_CONNECT)
            .env(envhub_hub::ENVHUB_MULTICAST, "0")
            .env(
                envhub_hub::env_vars::ENVHUB_NAMESPACE,
                format!("e2e_lf_{}_", std::process::id()),
            )
            .current_dir(&self.base)
            .stdin(Stdio::null());
        if let Some(run) = runtime {
            cmd.env("XDG_RUNTIME_DIR", run);
        }
        cmd
    }

    fn precious_unchanged(&self, after: &str) {
        assert_eq!(
            std::fs::read_to_string(&self.precious).unwrap(),
            PRECIOUS,
            "the victim's file changed after {after}"
        );
    }

    /// Every entry under the shared folder, with its owner.
    fn shared_entries(&self) -> Vec<(PathBuf, u32)> {
        fn walk(dir: &Path, out: &mut Vec<(PathBuf, u32)>) {
            let Ok(entries) = std::fs::read_dir(dir) else {
                return;
            };
            for e in entries.filter_map(Result::ok) {
                let meta = std::fs::symlink_metadata(e.path()).unwrap();
                out.push((e.path(), meta.uid()));
                if meta.is_dir() {
                    walk(&e.path(), out);
                }
            }
        }
        let mut out = Vec::new();
        walk(&self.shared, &mut out);
        out
    }
}

/// The name the built-in model folder had in the temporary folder (FNV-1a of names and
/// contents, as `builtin_assets.rs` computed it).
fn old_configs_name(uid: u32) -> String {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in "assets/planar_walker.xml"
        .bytes()
        .chain([0])
        .chain(PLANAR_WALKER.bytes())
        .chain([0])
    {
        h = (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3);
    }
    format!(
        "envhub-{uid}-configs-{}-{h:016x}",
        env!("CARGO_PKG_VERSION")
    )
}

/// The other user's traps: every folder envhub once made in the temporary folder, a link to
/// the victim's file at every name there envhub wrote, and at the temporary names of the
/// next pids (`.<pid>.<hash>`, `.credential-<pid>.tmp`, ...).
fn plant_everywhere(scene: &Scene) {
    let next = std::fs::read_to_string("/proc/sys/kernel/ns_last_pid")
        .ok()
        .and_then(|t| t.trim().parse::<u32>().ok())
        .unwrap_or(1000);
    let configs = old_configs_name(0);
    let hash = configs.rsplit('-').next().unwrap().to_string();
    let hash = u64::from_str_radix(&hash, 16).unwrap();
    let script = format!(
        r#"set -e
umask 000
mkdir -p "$S/{configs}/assets" "$S/envhub-0/hubs" "$S/envhub-0-installs" "$S/envhub"
ln -s "$T" "$S/{configs}/assets/planar_walker.xml"
for f in credential usrpwd; do ln -s "$T" "$S/envhub-0/hubs/$f"; done
ln -s "$T" "$S/envhub.sock"
pid={first}
while [ $pid -lt {last} ]; do
  ln -s "$T" "$S/{configs}/assets/.$pid.{hash}"
  for f in credential usrpwd $pid.json; do ln -s "$T" "$S/envhub-0/hubs/.$f-$pid.tmp"; done
  pid=$((pid+1))
done
"#,
        first = next + 1,
        last = next + 400,
    );
    scene.as_other_user(&script);
}

fn text(out: &Output) -> String {
    format!(
        "status {}\nstdout: {}\nstderr: {}",
        out.status,
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    )
}

#[test]
fn another_users_planted_folders_and_links_change_nothing_of_the_victims() {
    let test = "another_users_planted_folders_and_links_change_nothing_of_the_victims";
    if !supported(test) {
        return;
    }
    let scene = Scene::new("planted");
    plant_everywhere(&scene);
    let planted = scene.shared_entries();
    assert!(planted.iter().all(|(_, uid)| *uid == NOBODY));

    // A plain listing of the catalog.
    let out = scene.victim(&["envs"], None).output().unwrap();
    assert!(out.status.success(), "{}", text(&out));
    scene.precious_unchanged("`envhub envs`");
    let private = scene.home.join(".cache/envhub/run");
    let model = std::fs::read_dir(&private)
        .unwrap()
        .filter_map(Result::ok)
        .find(|e| e.file_name().to_string_lossy().starts_with("configs-"))
        .expect("the built-in model folder in the victim's private folder")
        .path()
        .join("assets/planar_walker.xml");
    assert_eq!(std::fs::read_to_string(&model).unwrap(), PLANAR_WALKER);
    let meta = std::fs::metadata(&private).unwrap();
    assert_eq!((meta.uid(), meta.mode() & 0o777), (0, 0o700));

    // A session on the built-in model.
    let hub = envhub_e2e::TestHub::new("local_files");
    if envhub_e2e::mujoco_available(&hub.hub, test) {
        let out = scene
            .victim(
                &[
                    "run",
                    "custom-mjcf-planar-walker",
                    "--steps",
                    "64",
                    "--json",
                ],
                None,
            )
            .output()
            .unwrap();
        assert!(out.status.success(), "{}", text(&out));
        scene.precious_unchanged("a session on `custom-mjcf-planar-walker`");
    }

    // A hub: its socket, its local entry and this user's local credential.
    let mut serve = scene
        .victim(
            &["serve", "--name", &format!("lf-{}", std::process::id())],
            None,
        )
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let stdout = serve.stdout.take().unwrap();
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let mut lines = std::io::BufReader::new(stdout).lines();
        let _ = tx.send(lines.next().and_then(Result::ok).unwrap_or_default());
    });
    let first = rx.recv_timeout(Duration::from_secs(60)).unwrap_or_default();
    let hubs = private.join("hubs");
    let deadline = Instant::now() + Duration::from_secs(30);
    let published = loop {
        let entry = std::fs::read_dir(&hubs).ok().and_then(|d| {
            d.filter_map(Result::ok)
                .find(|e| e.file_name().to_string_lossy().ends_with(".json"))
        });
        if entry.is_some() || Instant::now() > deadline {
            break entry.is_some();
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    let _ = serve.kill();
    let out = serve.wait_with_output().unwrap();
    assert!(
        first.contains(&private.join("envhub.sock").display().to_string()),
        "the hub did not listen in the victim's private folder: {first}\n{}",
        text(&out)
    );
    assert!(published, "the hub published no entry: {}", text(&out));
    for name in ["credential", "usrpwd"] {
        let meta = std::fs::symlink_metadata(hubs.join(name)).unwrap();
        assert!(meta.is_file(), "{name}");
        assert_eq!((meta.uid(), meta.mode() & 0o777), (0, 0o600), "{name}");
    }
    scene.precious_unchanged("`envhub serve`");

    // Nothing of the victim's in the shared folder: exactly what the other user planted.
    assert_eq!(scene.shared_entries(), planted);
}

#[test]
fn a_private_folder_another_user_made_first_is_refused_by_name() {
    let test = "a_private_folder_another_user_made_first_is_refused_by_name";
    if !supported(test) {
        return;
    }
    let scene = Scene::new("hostile");
    // The victim's runtime folder is a shared one (as when `su` keeps another user's, or a
    // login sets it wrong): there the other user makes `envhub` first, open to all, with a
    // link at the socket's name; in a second one it plants `envhub` as a link to a folder of
    // the victim's.
    let linked = scene.base.join("tmp2");
    std::fs::create_dir(&linked).unwrap();
    std::fs::set_permissions(&linked, std::fs::Permissions::from_mode(0o1777)).unwrap();
    scene.as_other_user(&format!(
        r#"set -e
umask 000
mkdir -p "$S/envhub/configs"
ln -s "$T" "$S/envhub/envhub.sock"
ln -s /root "{}/envhub"
"#,
        linked.display()
    ));
    for (runtime, why) in [
        (&scene.shared, "belongs to uid 65534"),
        (&linked, "is a symbolic link (owned by uid 65534)"),
    ] {
        let folder = runtime.join("envhub");
        for args in [&["envs"][..], &["serve", "--local-only"][..]] {
            let child = scene
                .victim(args, Some(runtime))
                .stdout(Stdio::piped())
                .stderr(Stdio::piped())
                .spawn()
                .unwrap();
            let out = wait_bounded(child, Duration::from_secs(60));
            let err = String::from_utf8_lossy(&out.stderr);
            assert!(
                !out.status.success(),
                "`envhub {}` used a folder of another user's: {}",
                args.join(" "),
                text(&out)
            );
            assert!(
                err.contains(&format!("`{}` {why}", folder.display())) && err.contains("hint:"),
                "`envhub {}` did not name the folder, what is wrong and the fix: {err}",
                args.join(" ")
            );
            scene.precious_unchanged(&format!("`envhub {}`", args.join(" ")));
        }
    }
    let linked_entries: Vec<_> = std::fs::read_dir(&linked)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(linked_entries, vec![std::ffi::OsString::from("envhub")]);
    // Nothing of the victim's was made in the other user's folders.
    assert!(
        scene.shared_entries().iter().all(|(_, uid)| *uid == NOBODY),
        "{:?}",
        scene.shared_entries()
    );
}

/// The output of `child`, killed if it runs past `limit` (a refusal is prompt; a hub that
/// wrongly started would serve forever).
fn wait_bounded(mut child: std::process::Child, limit: Duration) -> Output {
    let deadline = Instant::now() + limit;
    while child.try_wait().unwrap().is_none() && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(50));
    }
    let _ = child.kill();
    child.wait_with_output().unwrap()
}
