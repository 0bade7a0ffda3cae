//! `envhub lab`: hubs and clients on several machines that trust one another (a certificate
//! authority of the lab's own, a Zenoh config per member; see `envhub_net::lab`).

use super::Outcome;
use envhub_net::lab::{self, Role};
use std::path::PathBuf;

#[derive(clap::Args, Debug)]
pub(crate) struct Args {
    #[command(subcommand)]
    command: Command,
}

#[derive(clap::Subcommand, Debug)]
enum Command {
    /// Make a lab in FOLDER: its certificate authority (the key stays in FOLDER, mode 0600).
    Init {
        /// The lab's folder (made 0700; it must be this user's alone).
        folder: PathBuf,
        /// The lab's name, in its certificates.
        #[arg(long, default_value = "lab")]
        name: String,
    },
    /// Add a member (a machine's hubs and clients) to the lab: writes FOLDER/NAME.json5, the
    /// Zenoh config to copy to that machine and use with `--zenoh-config`, and writes the
    /// other members' configs again so that each checks NAME's hub name against NAME's
    /// certificate too (copy them again).
    Add {
        /// The lab's folder (made by `envhub lab init`).
        folder: PathBuf,
        /// The member's name (a machine's, say); names the file and its certificate.
        name: String,
        /// A Zenoh router members reach one another through (`mode: router`, listening on
        /// `tls/[::]:7447`), for networks where multicast does not reach every machine.
        #[arg(long, conflicts_with = "client")]
        router: bool,
        /// A client that reaches the lab through a router (`mode: client`: every message
        /// through the router). The default, a peer, finds hubs by multicast and links to
        /// each, but sees no hub through a router.
        #[arg(long)]
        client: bool,
    },
    /// Remove a member: the lab's CA is made anew and every other member's config signed
    /// again (copy each to its machine again); NAME's config, which trusts only the old CA,
    /// then links to no member.
    Remove {
        /// The lab's folder (made by `envhub lab init`).
        folder: PathBuf,
        /// The member to remove (its `NAME.json5` is deleted).
        name: String,
    },
    /// Run a Zenoh router from a router member's config (as `zenohd -c FILE` would), until
    /// interrupted.
    Router {
        /// The router's config (`envhub lab add FOLDER NAME --router`).
        #[arg(value_name = "CONFIG")]
        router_config: PathBuf,
    },
}

pub(crate) fn run(args: &Args) -> anyhow::Result<Outcome> {
    match &args.command {
        Command::Init { folder, name } => {
            lab::init(folder, name).map_err(anyhow::Error::msg)?;
            let f = folder.display();
            println!(
                "lab `{name}` made in {f}\n\
                 next: `envhub lab add {f} NAME` for each machine, copy NAME.json5 to it, then\n  \
                 hub:    envhub --zenoh-config NAME.json5 serve --listen tls/0.0.0.0:7447\n  \
                 client: envhub --zenoh-config NAME.json5 hubs"
            );
        }
        Command::Add {
            folder,
            name,
            router,
            client,
        } => {
            let role = match (router, client) {
                (true, _) => Role::Router,
                (_, true) => Role::RouterClient,
                _ => Role::Member,
            };
            let written = lab::add(folder, name, role).map_err(anyhow::Error::msg)?;
            let path = &written[0];
            let p = path.display();
            match role {
                Role::Member => println!(
                    "{p}: copy it to `{name}` (it holds {name}'s key), then\n  \
                     hub:    envhub --zenoh-config {name}.json5 serve --listen tls/0.0.0.0:7447\n  \
                     client: envhub --zenoh-config {name}.json5 hubs"
                ),
                Role::RouterClient => println!(
                    "{p}: copy it to `{name}` (it holds {name}'s key), then\n  \
                     client: envhub --zenoh-config {name}.json5 --connect tls/ROUTER:{} hubs",
                    lab::ROUTER_PORT
                ),
                Role::Router => println!(
                    "{p}: copy it to `{name}`, run `envhub lab router {name}.json5` (or \
                     `zenohd -c {name}.json5`) there, and give members `--connect tls/{name}:{}`",
                    lab::ROUTER_PORT
                ),
            }
            if written.len() > 1 {
                let others: Vec<String> = written[1..]
                    .iter()
                    .filter_map(|p| Some(p.file_stem()?.to_string_lossy().into_owned()))
                    .collect();
                println!(
                    "the other members' configs now name `{name}` too ({}): until each is \
                     copied to its machine again, that member does not check `{name}`'s hub name",
                    others.join(", ")
                );
            }
        }
        Command::Remove { folder, name } => {
            let rewritten = lab::remove(folder, name).map_err(anyhow::Error::msg)?;
            let f = folder.display();
            println!(
                "member `{name}` removed from the lab in {f}: its certificate authority is new, \
                 and `{name}`'s config links to no member that holds a new config"
            );
            if rewritten.is_empty() {
                println!("no member is left: add members with `envhub lab add {f} NAME`");
            } else {
                println!(
                    "next: copy each member's new config to its machine (it holds that member's \
                     key) and restart what runs there with it; a member still on its old config \
                     links with `{name}` and not with the members on new ones:"
                );
                for path in rewritten {
                    let member = path
                        .file_stem()
                        .map(|s| s.to_string_lossy().into_owned())
                        .unwrap_or_default();
                    println!("  {} -> {member}", path.display());
                }
            }
        }
        Command::Router { router_config } => router(router_config)?,
    }
    Ok(Outcome::Done)
}

/// Runs a router member's Zenoh router until the process is interrupted.
fn router(path: &std::path::Path) -> anyhow::Result<()> {
    use zenoh::Wait;
    let config = zenoh::Config::from_file(path)
        .map_err(|e| anyhow::anyhow!("cannot use `{}`: {e}", path.display()))?;
    let mode = config.get_json("mode").unwrap_or_default();
    anyhow::ensure!(
        mode == "\"router\"",
        "`{}` is not a router's config (its mode is {mode})\nhint: make one with `envhub lab \
         add FOLDER NAME --router`",
        path.display()
    );
    let session = zenoh::open(config)
        .wait()
        .map_err(|e| anyhow::anyhow!("the router cannot start: {e}"))?;
    let listening = session
        .info()
        .locators()
        .wait()
        .iter()
        .map(ToString::to_string)
        .collect::<Vec<_>>()
        .join(", ");
    println!("router listening on {listening}");
    loop {
        std::thread::park();
    }
}
