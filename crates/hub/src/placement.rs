//! Where a session's envs run: this machine, some hubs, every hub, or explicit counts.

use envhub_net::Network;
use envhub_protocol::HubError;
use envhub_session::{LOCAL, Slice};
use std::sync::Arc;
use std::time::Duration;

/// How long a session waits for the hubs it names to show up.
const NAMED_HUBS_WAIT: Duration = Duration::from_secs(3);

/// Where a session's envs run.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub enum Placement {
    /// On this machine (the default).
    #[default]
    Local,
    /// On these hubs (`local` is this machine), spread in proportion to their cores.
    Hubs(Vec<String>),
    /// On every live hub, spread in proportion to their cores.
    All,
    /// Explicit env counts per hub (`local` allowed), adding up to the number of envs.
    Counts(Vec<(String, usize)>),
}

impl std::str::FromStr for Placement {
    type Err = HubError;

    /// `local`, `all`, `a,b,local` or `a:4,b:4`.
    fn from_str(s: &str) -> Result<Placement, HubError> {
        let s = s.trim();
        match s {
            "" | LOCAL => return Ok(Placement::Local),
            "all" => return Ok(Placement::All),
            _ => {}
        }
        let parts: Vec<&str> = s.split(',').map(str::trim).collect();
        if parts.iter().all(|p| p.contains(':')) {
            let counts = parts
                .iter()
                .map(|p| {
                    let (name, n) = p.rsplit_once(':').expect("checked");
                    n.parse::<usize>().map(|n| (name.to_string(), n)).map_err(|_| {
                        HubError::InvalidConfig {
                            what: "hubs",
                            reason: format!(
                                "`{p}`: the count after `:` must be a whole number, as in `box1:64,box2:64`"
                            ),
                        }
                    })
                })
                .collect::<Result<_, _>>()?;
            return Ok(Placement::Counts(counts));
        }
        if parts.iter().any(|p| p.contains(':')) {
            return Err(HubError::InvalidConfig {
                what: "hubs",
                reason: format!(
                    "`{s}` mixes names with and without counts; give a count for every hub (`a:4,b:4`) or none (`a,b`)"
                ),
            });
        }
        Ok(Placement::Hubs(
            parts.into_iter().map(String::from).collect(),
        ))
    }
}

impl Placement {
    /// Whether every env runs on this machine.
    pub fn is_local(&self) -> bool {
        match self {
            Placement::Local => true,
            Placement::Hubs(names) => names.iter().all(|n| n == LOCAL),
            Placement::Counts(counts) => counts.iter().all(|(n, _)| n == LOCAL),
            Placement::All => false,
        }
    }
}

/// Turns a placement into slices for `num_envs` envs (hubs asked for their cores).
pub(crate) fn resolve(
    placement: &Placement,
    num_envs: usize,
    network: Option<&Arc<Network>>,
) -> Result<Vec<Slice>, HubError> {
    let need_network = || {
        network.ok_or_else(|| HubError::Network {
            reason: "this placement names hubs, but no network is configured".into(),
            hint: "connect to the hubs' network (`--connect`, ENVHUB_CONNECT or `zenoh:` in envhub.yaml)".into(),
        })
    };
    let names: Vec<String> = match placement {
        Placement::Local => {
            return Ok(vec![Slice {
                place: LOCAL.into(),
                num_envs,
            }]);
        }
        Placement::Counts(counts) => {
            let total: usize = counts.iter().map(|(_, n)| n).sum();
            if total != num_envs {
                return Err(HubError::InvalidConfig {
                    what: "hubs",
                    reason: format!(
                        "the counts add up to {total}, but the session has {num_envs} envs"
                    ),
                });
            }
            check_repeats(counts.iter().map(|(n, _)| n))?;
            let remote: Vec<String> = counts
                .iter()
                .filter(|(n, _)| n != LOCAL)
                .map(|(n, _)| n.clone())
                .collect();
            if !remote.is_empty() {
                need_network()?.wait_for(&remote, NAMED_HUBS_WAIT)?;
            }
            return Ok(counts
                .iter()
                .filter(|(_, n)| *n > 0)
                .map(|(place, n)| Slice {
                    place: place.clone(),
                    num_envs: *n,
                })
                .collect());
        }
        Placement::Hubs(names) => {
            check_repeats(names.iter())?;
            let remote: Vec<String> = names.iter().filter(|n| *n != LOCAL).cloned().collect();
            if !remote.is_empty() {
                need_network()?.wait_for(&remote, NAMED_HUBS_WAIT)?;
            }
            names.clone()
        }
        Placement::All => {
            let live = need_network()?.live_hubs(envhub_net::DISCOVERY);
            if live.is_empty() {
                return Err(HubError::UnknownHub {
                    name: "all".into(),
                    live: "none".into(),
                    closest: String::new(),
                });
            }
            live
        }
    };
    let mut cores = Vec::with_capacity(names.len());
    for name in &names {
        cores.push(if name == LOCAL {
            envhub_session::cores()
        } else {
            let network = need_network()?;
            let info: envhub_protocol::HubInfo = network.query(
                name,
                &envhub_protocol::keys::hub_info(name),
                None,
                Duration::from_secs(3),
            )?;
            info.cores.max(1)
        });
    }
    Ok(names
        .into_iter()
        .zip(split_by_weight(num_envs, &cores))
        .filter(|(_, n)| *n > 0)
        .map(|(place, num_envs)| Slice { place, num_envs })
        .collect())
}

fn check_repeats<'a>(names: impl Iterator<Item = &'a String>) -> Result<(), HubError> {
    let mut seen = std::collections::HashSet::new();
    for n in names {
        if !seen.insert(n) {
            return Err(HubError::InvalidConfig {
                what: "hubs",
                reason: format!("hub `{n}` is named twice"),
            });
        }
    }
    Ok(())
}

/// Splits `n` in proportion to `weights` (largest remainders get the leftovers; ties go to
/// the first), so the counts add up to `n` exactly.
pub(crate) fn split_by_weight(n: usize, weights: &[usize]) -> Vec<usize> {
    let total: usize = weights.iter().sum::<usize>().max(1);
    let mut counts: Vec<usize> = weights.iter().map(|w| n * w / total).collect();
    let mut left = n - counts.iter().sum::<usize>();
    let mut order: Vec<usize> = (0..weights.len()).collect();
    order.sort_by_key(|&i| std::cmp::Reverse((n * weights[i]) % total));
    for &i in order.iter().cycle() {
        if left == 0 {
            break;
        }
        counts[i] += 1;
        left -= 1;
    }
    counts
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn placements_parse() {
        assert_eq!("local".parse::<Placement>().unwrap(), Placement::Local);
        assert_eq!("all".parse::<Placement>().unwrap(), Placement::All);
        assert_eq!(
            "a, b".parse::<Placement>().unwrap(),
            Placement::Hubs(vec!["a".into(), "b".into()])
        );
        assert_eq!(
            "a:3,local:1".parse::<Placement>().unwrap(),
            Placement::Counts(vec![("a".into(), 3), ("local".into(), 1)])
        );
        let e = "a:3,b".parse::<Placement>().unwrap_err().to_string();
        assert!(e.contains("mixes"), "{e}");
        let e = "a:x".parse::<Placement>().unwrap_err().to_string();
        assert!(e.contains("whole number"), "{e}");
    }

    #[test]
    fn envs_spread_in_proportion_to_cores() {
        assert_eq!(split_by_weight(10, &[32, 32]), vec![5, 5]);
        assert_eq!(split_by_weight(12, &[2, 16, 6]), vec![1, 8, 3]);
        assert_eq!(split_by_weight(7, &[1, 1, 1]), vec![3, 2, 2]);
        assert_eq!(split_by_weight(1, &[4, 4]).iter().sum::<usize>(), 1);
        assert_eq!(split_by_weight(0, &[4, 4]), vec![0, 0]);
    }
}
