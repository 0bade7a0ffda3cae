//! The several-machines recipe of docs/guide/remote.md, exactly, on two "machines" (network
//! namespaces joined by a veth, see `remote_netns`): `envhub lab init`, `envhub lab add` per
//! member, then
//! - a hub of the lab is found by a client of the lab by multicast alone and runs its session,
//!   while a client of another lab, or one without a certificate, sees no hub even given the
//!   endpoint;
//! - through a router (`envhub lab router`, the Zenoh router as `zenohd` runs it): a hub that
//!   only the router can reach and a client on the other machine that reaches only the router
//!   meet and run a session; an outsider reaching the router sees nothing.
//!
//! Skipped as `remote_netns` is (root, `ip`, `unshare`; `ENVHUB_NETNS_REQUIRED` fails a skip).

use crate::remote_netns::{TwoHosts, run_summary};
use envhub_e2e::binary;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

/// A lab with `members` (name, `envhub lab add` flag), and another lab with members `mallory`
/// (a peer) and `mallory-c` (a client); their configs' paths by name.
/// Made outside `/tmp` (each namespace gets a fresh one) beside the binaries, which the
/// namespaces see.
fn labs(tag: &str, members: &[(&str, &str)]) -> (PathBuf, impl Fn(&str) -> String) {
    let root = envhub_e2e::bin_dir().join(format!("e2e-lab-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&root);
    let lab = |args: &[&str]| {
        let out = Command::new(binary("envhub"))
            .arg("lab")
            .args(args)
            .output()
            .expect("envhub runs");
        assert!(
            out.status.success(),
            "envhub lab {args:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    };
    let (ours, theirs) = (root.join("ours"), root.join("theirs"));
    let s = |p: &Path| p.display().to_string();
    lab(&["init", &s(&ours), "--name", "ours"]);
    let ours_dir = s(&ours);
    for (member, flag) in members {
        let mut args = vec!["add", ours_dir.as_str(), member];
        if !flag.is_empty() {
            args.push(flag);
        }
        lab(&args);
    }
    lab(&["init", &s(&theirs), "--name", "theirs"]);
    lab(&["add", &s(&theirs), "mallory"]);
    lab(&["add", &s(&theirs), "mallory-c", "--client"]);
    let dir = root.clone();
    (root, move |member: &str| {
        let lab = if member.starts_with("mallory") {
            "theirs"
        } else {
            "ours"
        };
        s(&dir.join(lab).join(format!("{member}.json5")))
    })
}

/// Where hub `hub` of a lab test puts its socket (the default one is shared by every test's
/// hubs): in the lab's folder, which the namespaces see.
fn socket_in(root: &Path, hub: &str) -> String {
    root.join("ours")
        .join(format!("{hub}.sock"))
        .display()
        .to_string()
}

/// `envhub --zenoh-config CONFIG [ARGS] hubs --json` on host 1, asked up to `tries` times
/// until it lists `name` (discovery over a veth can take more than one 2 s window): the
/// names it listed last.
fn hubs_from_b(
    hosts: &TwoHosts,
    tag: &str,
    config: &str,
    args: &[&str],
    vars: &[(&str, &str)],
    name: &str,
    tries: usize,
) -> Vec<String> {
    let mut names = Vec::new();
    for k in 0..tries {
        let mut all = vec!["--zenoh-config", config];
        all.extend_from_slice(args);
        all.extend_from_slice(&["hubs", "--json"]);
        let (_, out, _) = hosts
            .envhub_with(1, &format!("{tag}-{k}"), &all, vars)
            .finish(60);
        let listed: Vec<serde_json::Value> = serde_json::from_str(&out).unwrap_or_default();
        names = listed
            .iter()
            .filter_map(|h| h["name"].as_str().map(String::from))
            .collect();
        if names.iter().any(|n| n == name) {
            break;
        }
    }
    names
}

/// A 200-step CartPole rollout on hub `hub`, from host 1.
fn run_on(hosts: &TwoHosts, config: &str, args: &[&str], vars: &[(&str, &str)], hub: &str) {
    let mut all = vec!["--zenoh-config", config];
    all.extend_from_slice(args);
    all.extend_from_slice(&[
        "run",
        "gym-cartpole",
        "--hub",
        hub,
        "--num-envs",
        "2",
        "--steps",
        "200",
        "--json",
    ]);
    let (status, out, err) = hosts.envhub_with(1, "run", &all, vars).finish(120);
    let summary = run_summary(status, &out, &err, "a lab client's run");
    assert_eq!(summary["steps"], 200, "{summary}");
}

#[test]
fn netns_lab_members_find_and_use_each_other_and_outsiders_see_nothing() {
    let test = "netns_lab_members_find_and_use_each_other_and_outsiders_see_nothing";
    let Some(hosts) = TwoHosts::new(test) else {
        return;
    };
    let (root, config) = labs("peers", &[("box-a", ""), ("you", "")]);
    let socket = |hub: &str| socket_in(&root, hub);
    let listen = format!("tls/{}:7447", hosts.addr[0]);
    let box_a = config("box-a");
    let mut hub = hosts.envhub(
        0,
        "hub-a",
        &[
            "--zenoh-config",
            &box_a,
            "serve",
            "--name",
            "a",
            "--listen",
            &listen,
            "--socket",
            &socket("a"),
        ],
    );
    hub.wait_for_line("on the network as hub `a`", Duration::from_secs(60));
    // Multicast left to the lab's default (on: every link is checked at both ends).
    let default_multicast = [(envhub_hub::ENVHUB_MULTICAST, "")];
    let you = config("you");
    let seen = hubs_from_b(&hosts, "you", &you, &[], &default_multicast, "a", 5);
    assert_eq!(
        seen,
        ["a"],
        "a client of the lab did not find its hub by multicast"
    );
    run_on(&hosts, &you, &[], &default_multicast, "a");
    // Outsiders, given the endpoint: a client of another lab, and one without a certificate.
    let mallory = config("mallory");
    let seen = hubs_from_b(
        &hosts,
        "mallory",
        &mallory,
        &["--connect", &listen],
        &[],
        "a",
        1,
    );
    assert!(seen.is_empty(), "a client of another lab saw {seen:?}");
    let (_, out, err) = hosts
        .envhub(1, "bare", &["--connect", &listen, "hubs", "--json"])
        .finish(60);
    assert!(
        !out.contains("\"a\""),
        "a client without a certificate saw hub a: {out}{err}"
    );
    drop(hub);
    let _ = std::fs::remove_dir_all(root);
}

#[test]
fn netns_a_hub_and_a_client_of_a_lab_meet_through_a_router() {
    let test = "netns_a_hub_and_a_client_of_a_lab_meet_through_a_router";
    let Some(hosts) = TwoHosts::new(test) else {
        return;
    };
    let (root, config) = labs(
        "router",
        &[("hop", "--router"), ("box-b", ""), ("you", "--client")],
    );
    let socket = |hub: &str| socket_in(&root, hub);
    let mut router = hosts.envhub(0, "router", &["lab", "router", &config("hop")]);
    router.wait_for_line("router listening on", Duration::from_secs(60));
    // Hub `b` listens on host 0's loopback only and connects to the router: only the router
    // can reach it from host 1.
    let box_b = config("box-b");
    let mut hub = hosts.envhub(
        0,
        "hub-b",
        &[
            "--zenoh-config",
            &box_b,
            "--connect",
            "tls/127.0.0.1:7447",
            "serve",
            "--name",
            "b",
            "--listen",
            "tls/127.0.0.1:7448",
            "--socket",
            &socket("b"),
        ],
    );
    hub.wait_for_line("on the network as hub `b`", Duration::from_secs(60));
    let via_router = format!("tls/{}:7447", hosts.addr[0]);
    let no_multicast = [(envhub_hub::ENVHUB_MULTICAST, "0")];
    let you = config("you");
    let at_router = ["--connect", via_router.as_str()];
    let seen = hubs_from_b(&hosts, "you", &you, &at_router, &no_multicast, "b", 5);
    assert_eq!(
        seen,
        ["b"],
        "a client of the lab did not find hub b through the router"
    );
    run_on(&hosts, &you, &at_router, &no_multicast, "b");
    let mallory = config("mallory-c");
    let seen = hubs_from_b(
        &hosts,
        "mallory",
        &mallory,
        &at_router,
        &no_multicast,
        "b",
        1,
    );
    assert!(
        seen.is_empty(),
        "a client of another lab saw {seen:?} through the router"
    );
    drop(hub);
    drop(router);
    let _ = std::fs::remove_dir_all(root);
}

/// `envhub lab remove`: the removed machine keeps its copy of its config, and with it links to
/// no member that holds a new config, as a client given a member hub's endpoint or as a hub a
/// member is given the endpoint of; a remaining member's new config finds the lab's hub as
/// before. Removing a name that is not a member names the members.
#[test]
fn netns_a_removed_member_links_to_no_member() {
    let test = "netns_a_removed_member_links_to_no_member";
    let Some(hosts) = TwoHosts::new(test) else {
        return;
    };
    let (root, config) = labs("remove", &[("box-a", ""), ("you", ""), ("gone", "")]);
    let kept = root.join("gone-kept.json5").display().to_string();
    std::fs::copy(config("gone"), &kept).unwrap();
    let ours = root.join("ours").display().to_string();
    let lab = |args: &[&str]| {
        let out = Command::new(binary("envhub"))
            .arg("lab")
            .args(args)
            .output()
            .expect("envhub runs");
        let text = |b: &[u8]| String::from_utf8_lossy(b).into_owned();
        (out.status.success(), text(&out.stdout), text(&out.stderr))
    };
    let (ok, _, err) = lab(&["remove", &ours, "nobody"]);
    assert!(
        !ok && err.contains("`nobody` is not a member") && err.contains("box-a, gone, you"),
        "{err}"
    );
    let (ok, out, err) = lab(&["remove", &ours, "gone"]);
    assert!(ok, "envhub lab remove: {err}");
    assert!(
        out.contains("box-a.json5 -> box-a") && out.contains("you.json5 -> you"),
        "{out}"
    );
    let socket = |hub: &str| socket_in(&root, hub);
    let (listen_a, listen_g) = (
        format!("tls/{}:7447", hosts.addr[0]),
        format!("tls/{}:7447", hosts.addr[1]),
    );
    let box_a = config("box-a");
    let serve = |side: usize, tag: &str, config: &str, name: &str, listen: &str| {
        let mut hub = hosts.envhub(
            side,
            tag,
            &[
                "--zenoh-config",
                config,
                "serve",
                "--name",
                name,
                "--listen",
                listen,
                "--socket",
                &socket(name),
            ],
        );
        hub.wait_for_line(
            &format!("on the network as hub `{name}`"),
            Duration::from_secs(60),
        );
        hub
    };
    let hub_a = serve(0, "hub-a", &box_a, "a", &listen_a);
    // The removed member's hub, on the other machine, listening on its veth.
    let hub_g = serve(1, "hub-g", &kept, "g", &listen_g);
    let default_multicast = [(envhub_hub::ENVHUB_MULTICAST, "")];
    // A remaining member, given the removed one's endpoint too: finds `a`, never `g`.
    let you = config("you");
    let at_g = ["--connect", listen_g.as_str()];
    let seen = hubs_from_b(&hosts, "you", &you, &at_g, &default_multicast, "a", 5);
    assert_eq!(seen, ["a"], "a remaining member's new config");
    // The removed member as a client, given `a`'s endpoint: its own hub at most, never `a`.
    let at_a = ["--connect", listen_a.as_str()];
    let seen = hubs_from_b(&hosts, "gone", &kept, &at_a, &default_multicast, "a", 2);
    assert!(
        !seen.iter().any(|h| h == "a"),
        "the removed member's config reached hub a: {seen:?}"
    );
    drop(hub_g);
    drop(hub_a);
    let _ = std::fs::remove_dir_all(root);
}

/// Hub names checked against certificates: member `imp` serves a hub named `a` (member `a`'s
/// name) before `a` does. A client of the lab, at first contact (no pin), lists no `a` then;
/// `a`'s own hub starts beside the impostor (which it does not see as a namesake), and the
/// client lists it and runs its session there.
#[test]
fn netns_a_member_cannot_pose_as_another_member_s_hub() {
    let test = "netns_a_member_cannot_pose_as_another_member_s_hub";
    let Some(hosts) = TwoHosts::new(test) else {
        return;
    };
    let (root, config) = labs("names", &[("a", ""), ("imp", ""), ("you", "")]);
    let (listen_a, listen_imp) = (
        format!("tls/{}:7447", hosts.addr[0]),
        format!("tls/{}:7447", hosts.addr[1]),
    );
    let serve = |side: usize, tag: &str, member: &str, listen: &str| {
        let mut hub = hosts.envhub(
            side,
            tag,
            &[
                "--zenoh-config",
                &config(member),
                "serve",
                "--name",
                "a",
                "--listen",
                listen,
                "--socket",
                &socket_in(&root, tag),
            ],
        );
        hub.wait_for_line("on the network as hub `a`", Duration::from_secs(60));
        hub
    };
    let impostor = serve(1, "imp", "imp", &listen_imp);
    let default_multicast = [(envhub_hub::ENVHUB_MULTICAST, "")];
    let you = config("you");
    let at_imp = ["--connect", listen_imp.as_str()];
    let seen = hubs_from_b(&hosts, "first", &you, &at_imp, &default_multicast, "a", 2);
    assert!(seen.is_empty(), "a member posed as hub `a`: {seen:?}");
    let real = serve(0, "real", "a", &listen_a);
    let seen = hubs_from_b(&hosts, "you", &you, &at_imp, &default_multicast, "a", 5);
    assert_eq!(seen, ["a"], "the lab's client did not find member a's hub");
    run_on(&hosts, &you, &at_imp, &default_multicast, "a");
    drop(real);
    drop(impostor);
    let _ = std::fs::remove_dir_all(root);
}
