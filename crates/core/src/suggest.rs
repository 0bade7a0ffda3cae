//! "Did you mean": the closest names to a typo.

/// Up to `max` candidates closest to `needle`, best first; only reasonably close ones.
pub fn closest<'a>(
    needle: &str,
    candidates: impl IntoIterator<Item = &'a str>,
    max: usize,
) -> Vec<String> {
    let needle_l = needle.to_lowercase();
    let mut scored: Vec<(f64, &str)> = candidates
        .into_iter()
        .map(|c| {
            let c_l = c.to_lowercase();
            let mut score = strsim::jaro_winkler(&needle_l, &c_l);
            // A candidate that contains the needle (or the reverse) is a strong hint.
            if needle_l.len() >= 3 && (c_l.contains(&needle_l) || needle_l.contains(&c_l)) {
                score = score.max(0.9);
            }
            (score, c)
        })
        .filter(|(s, _)| *s >= 0.75)
        .collect();
    scored.sort_by(|a, b| b.0.total_cmp(&a.0));
    scored
        .into_iter()
        .take(max)
        .map(|(_, c)| c.to_string())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::closest;

    #[test]
    fn suggests_near_names() {
        let ids = ["mujoco-ant", "mujoco-hopper", "gym-cartpole", "fetch-push"];
        assert_eq!(closest("mujoco-ants", ids, 3)[0], "mujoco-ant");
        assert_eq!(closest("cartpole", ids, 3), vec!["gym-cartpole"]);
        assert!(closest("zzzzzz", ids, 3).is_empty());
    }
}
