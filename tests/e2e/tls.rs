//! A hub on TLS with client certificates and Zenoh's access control, as docs/design/security.md
//! sets it up: a client with a certificate of the lab's CA and an allowed name runs envs; one
//! of another CA sees no hub; one of the lab's CA with a name the rules do not allow sees no
//! hub either. Certificates are made by `openssl` for each run.

use envhub_e2e::remote::{RemoteHub, free_port};
use envhub_hub::{EnvConfig, Hub, NetConfig, Placement, Registry, SessionOptions};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Duration;
use zenoh::Wait;

fn openssl(dir: &Path, args: &[&str]) {
    let out = Command::new("openssl")
        .current_dir(dir)
        .args(args)
        .output()
        .expect("openssl runs (Debian's `openssl` package)");
    assert!(
        out.status.success(),
        "openssl {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// A certificate `NAME.pem` / `NAME.key` for common name `cn`, signed by CA `ca`.
fn leaf(dir: &Path, ca: &str, name: &str, cn: &str) {
    let ext = dir.join(format!("{name}.ext"));
    std::fs::write(
        &ext,
        "subjectAltName=DNS:localhost,IP:127.0.0.1\nbasicConstraints=CA:FALSE\nkeyUsage=digitalSignature\nextendedKeyUsage=serverAuth,clientAuth\n",
    )
    .unwrap();
    let (key, csr, pem) = (
        format!("{name}.key"),
        format!("{name}.csr"),
        format!("{name}.pem"),
    );
    openssl(
        dir,
        &[
            "req",
            "-newkey",
            "ec",
            "-pkeyopt",
            "ec_paramgen_curve:prime256v1",
            "-nodes",
            "-keyout",
            &key,
            "-out",
            &csr,
            "-subj",
            &format!("/CN={cn}"),
        ],
    );
    openssl(
        dir,
        &[
            "x509",
            "-req",
            "-in",
            &csr,
            "-CA",
            &format!("{ca}.pem"),
            "-CAkey",
            &format!("{ca}.key"),
            "-CAcreateserial",
            "-out",
            &pem,
            "-days",
            "2",
            "-extfile",
            &format!("{name}.ext"),
        ],
    );
}

/// A client's Zenoh config: TLS to the hub with `cert`, trusting CA `ca`.
fn client_config(dir: &Path, ca: &str, cert: &str) -> PathBuf {
    let path = dir.join(format!("client-{cert}.json5"));
    let p = |f: String| dir.join(f).display().to_string();
    std::fs::write(
        &path,
        format!(
            r#"{{
  mode: "peer",
  scouting: {{ multicast: {{ enabled: false }} }},
  transport: {{ link: {{ protocols: ["tls"], tls: {{
    root_ca_certificate: "{}",
    connect_certificate: "{}",
    connect_private_key: "{}",
    enable_mtls: true,
  }} }} }},
}}"#,
            p(format!("{ca}.pem")),
            p(format!("{cert}.pem")),
            p(format!("{cert}.key")),
        ),
    )
    .unwrap();
    path
}

fn client(name: &str, endpoint: &str, config: PathBuf) -> Hub {
    Hub::new(Registry::builtin())
        .with_options(SessionOptions {
            namespace: format!("e2e_tls_{name}_{}_", std::process::id()),
            step_timeout: Duration::from_secs(10),
            start_timeout: Duration::from_secs(30),
            ..SessionOptions::default()
        })
        .with_network(NetConfig {
            connect: vec![endpoint.to_string()],
            multicast: Some(false),
            config: Some(config),
            ..NetConfig::default()
        })
}

#[test]
fn only_clients_with_the_lab_s_certificate_and_an_allowed_name_reach_a_tls_hub() {
    let dir = std::env::temp_dir().join(format!("e2e-tls-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    for name in ["lab-ca", "other-ca"] {
        openssl(
            &dir,
            &[
                "req",
                "-x509",
                "-newkey",
                "ec",
                "-pkeyopt",
                "ec_paramgen_curve:prime256v1",
                "-nodes",
                "-keyout",
                &format!("{name}.key"),
                "-out",
                &format!("{name}.pem"),
                "-days",
                "2",
                "-subj",
                &format!("/CN={name}"),
            ],
        );
    }
    leaf(&dir, "lab-ca", "hub", "hub");
    leaf(&dir, "lab-ca", "trainer", "trainer");
    leaf(&dir, "lab-ca", "intruder", "intruder");
    leaf(&dir, "other-ca", "stranger", "trainer");

    let endpoint = format!("tls/127.0.0.1:{}", free_port());
    let p = |f: &str| dir.join(f).display().to_string();
    let hub_config = dir.join("hub.json5");
    std::fs::write(
        &hub_config,
        format!(
            r#"{{
  transport: {{ link: {{ tls: {{
    root_ca_certificate: "{ca}",
    listen_certificate: "{cert}",
    listen_private_key: "{key}",
    connect_certificate: "{cert}",
    connect_private_key: "{key}",
    enable_mtls: true,
  }} }} }},
  access_control: {{
    enabled: true,
    default_permission: "deny",
    rules: [{{
      id: "envhub",
      permission: "allow",
      flows: ["ingress", "egress"],
      messages: ["put", "delete", "declare_subscriber", "query", "reply", "declare_queryable",
                 "liveliness_token", "declare_liveliness_subscriber", "liveliness_query"],
      key_exprs: ["envhub/**"],
    }}],
    subjects: [{{ id: "trainers", cert_common_names: ["trainer"] }}],
    policies: [{{ rules: ["envhub"], subjects: ["trainers"] }}],
  }},
}}"#,
            ca = p("lab-ca.pem"),
            cert = p("hub.pem"),
            key = p("hub.key"),
        ),
    )
    .unwrap();
    let hub_config_arg = hub_config.display().to_string();
    let a = RemoteHub::start_at(
        "tlshub",
        &endpoint,
        &["--zenoh-config", &hub_config_arg],
        &[],
    );
    let on_a = Placement::Hubs(vec![a.name.clone()]);
    let config = EnvConfig::default();

    // Listeners on every envhub key while a trainer steps: one with an allowed name (the
    // control: it hears the session's traffic), one of the lab's CA with a name the rules do
    // not allow (hears nothing).
    let listen = |cert: &str| {
        let mut config = zenoh::Config::from_file(client_config(&dir, "lab-ca", cert)).unwrap();
        config
            .insert_json5("connect/endpoints", &format!("[\"{endpoint}\"]"))
            .unwrap();
        // Listening on nothing, as envhub's clients do: a peer that listens would be found
        // through the hub's gossip and connected to by the trainer directly (docs/design/security.md).
        config.insert_json5("listen/endpoints", "[]").unwrap();
        let session = zenoh::open(config).wait().unwrap();
        let heard = Arc::new(AtomicUsize::new(0));
        let count = heard.clone();
        let subscriber = session
            .declare_subscriber("envhub/**")
            .callback(move |_| {
                count.fetch_add(1, Ordering::Relaxed);
            })
            .wait()
            .unwrap();
        (session, subscriber, heard)
    };
    let (_s1, _sub1, heard_by_trainer) = listen("trainer");
    let (_s2, _sub2, heard_by_intruder) = listen("intruder");
    std::thread::sleep(Duration::from_millis(500));

    let trainer = client(
        "trainer",
        &endpoint,
        client_config(&dir, "lab-ca", "trainer"),
    );
    let mut env = trainer
        .make_vec_on("gym-cartpole", 2, &config, &on_a)
        .expect("a client with the lab's certificate and an allowed name runs envs");
    env.reset(Some(0)).unwrap();
    let action = vec![0u8; 2 * env.action_space().byte_len()];
    for _ in 0..50 {
        env.step(&action).unwrap();
    }
    drop(env);
    std::thread::sleep(Duration::from_millis(300));
    assert!(
        heard_by_trainer.load(Ordering::Relaxed) >= 50,
        "the control listener heard {} messages of the session",
        heard_by_trainer.load(Ordering::Relaxed)
    );
    assert_eq!(
        heard_by_intruder.load(Ordering::Relaxed),
        0,
        "a peer whose name the rules do not allow read the session's traffic"
    );

    for (who, ca) in [("stranger", "other-ca"), ("intruder", "lab-ca")] {
        let outsider = client(who, &endpoint, client_config(&dir, ca, who));
        match outsider.make_vec_on("gym-cartpole", 1, &config, &on_a) {
            Ok(_) => panic!("`{who}` ran envs on the TLS hub"),
            Err(e) => {
                let text = e.to_string();
                assert!(text.contains("tlshub"), "`{who}`: {text}");
            }
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}
