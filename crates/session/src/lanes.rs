//! Lanes: a remote hub's slice of a session opened as several sessions of its own, each
//! taking its own requests, so that one steps while another's results travel
//! ([`crate::SessionOptions::remote_lanes`]).

/// A remote slice of `num_envs` envs as `lanes` sessions on its hub: per lane, its first env
/// (from the slice's start), its envs and its workers. At most one lane per env and, when
/// `workers` is set, one per worker: the slice's workers are split among the lanes, so the
/// hub runs as many worker processes as it would for one session. Lanes of `workers: None`
/// leave the count to the hub, as a one-session slice does.
pub(crate) fn split(
    num_envs: usize,
    lanes: usize,
    workers: Option<usize>,
) -> Vec<(usize, usize, Option<usize>)> {
    let k = lanes
        .max(1)
        .min(num_envs.max(1))
        .min(workers.unwrap_or(usize::MAX).max(1));
    let shares = workers.map(|w| crate::worker_link::split_envs(w, k));
    crate::worker_link::split_envs(num_envs, k)
        .into_iter()
        .enumerate()
        .map(|(i, (offset, n))| (offset, n, shares.as_ref().map(|s| s[i].1.min(n))))
        .collect()
}
