//! Words and stems: how task descriptions and tags are compared.
//!
//! A small suffix stemmer is enough here: tags are short English task words, and what
//! matters is that `running`, `runs` and `run` meet, and that `pen` does not match
//! `pendulum` nor `a` match everything.

/// Words too common to say anything about a task.
const STOP_WORDS: &[&str] = &[
    "a",
    "an",
    "and",
    "any",
    "are",
    "as",
    "at",
    "be",
    "by",
    "can",
    "do",
    "for",
    "from",
    "get",
    "has",
    "have",
    "in",
    "into",
    "is",
    "it",
    "its",
    "make",
    "of",
    "on",
    "onto",
    "or",
    "out",
    "so",
    "some",
    "that",
    "the",
    "their",
    "then",
    "there",
    "this",
    "to",
    "up",
    "use",
    "using",
    "while",
    "with",
    "without",
    "robot",
    "learn",
    "learns",
    "task",
    "should",
    "must",
    "will",
    "through",
    "across",
    "over",
    "under",
    "along",
    "around",
    "very",
    "when",
    "where",
    "which",
    "what",
    "how",
    "much",
    "more",
    "most",
    "possible",
    "learning",
    "train",
    "training",
    "policy",
    "agent",
    "environment",
    "env",
    "simulation",
    "sim",
    "we",
    "want",
    "like",
    "all",
    "each",
    "way",
    "one",
    "two",
    "three",
];

/// Lower-cased words of `text`: punctuation stripped, hyphenated compounds split
/// (`pick-and-place` gives `pick`, `and`, `place`), stop words and one-letter words dropped.
pub(crate) fn words(text: &str) -> Vec<String> {
    let mut out: Vec<String> = Vec::new();
    for raw in text.split(|c: char| !(c.is_alphanumeric() || c == '_')) {
        let w = raw.to_lowercase();
        if w.chars().count() < 2 || STOP_WORDS.contains(&w.as_str()) {
            continue;
        }
        if !out.contains(&w) {
            out.push(w);
        }
    }
    out
}

/// The stem of a lower-case word: common suffixes removed, a doubled final consonant
/// undoubled (`running` → `run`) and a final `e` dropped (`place`/`placed`/`placing` → `plac`).
pub(crate) fn stem(word: &str) -> String {
    let w = word.to_lowercase();
    let n = w.len();
    // A suffix is only a suffix if what remains still looks like a word (`swing` stays).
    let keeps_word = |rest: &str| rest.len() >= 3 && rest.contains(['a', 'e', 'i', 'o', 'u', 'y']);
    let mut s: &str = &w;
    let mut undouble = false;
    if w.ends_with("ing") && keeps_word(&w[..n - 3]) {
        s = &w[..n - 3];
        undouble = true;
    } else if ((w.ends_with("ed") && !w.ends_with("eed")) || (n > 5 && w.ends_with("er")))
        && keeps_word(&w[..n - 2])
    {
        s = &w[..n - 2];
        undouble = true;
    } else if n > 4 && w.ends_with("ies") {
        return format!("{}y", &w[..n - 3]);
    } else if n > 3
        && w.ends_with("es")
        && ["s", "x", "z", "ch", "sh"]
            .iter()
            .any(|e| w[..n - 2].ends_with(e))
    {
        s = &w[..n - 2];
    } else if n > 3 && w.ends_with('s') && !w.ends_with("ss") && !w.ends_with("us") {
        s = &w[..n - 1];
    }
    let mut stem = s.to_string();
    let b = stem.as_bytes();
    if undouble
        && b.len() >= 3
        && b[b.len() - 1] == b[b.len() - 2]
        && !b"aeioulsz".contains(&b[b.len() - 1])
    {
        stem.pop();
    }
    if stem.len() > 3 && stem.ends_with('e') {
        stem.pop();
    }
    stem
}

/// Whether two stems name the same thing: equal, or one a short extension of the other
/// (`manipulat` / `manipulation`) when the shorter is long enough to mean something.
pub(crate) fn stems_match(a: &str, b: &str) -> bool {
    if a == b {
        return true;
    }
    let (short, long) = if a.len() <= b.len() { (a, b) } else { (b, a) };
    short.len() >= 4 && long.len() - short.len() <= 4 && long.starts_with(short)
}

/// The stems an entry offers for one of its tags: the tag itself and, for a compound
/// (`pick-and-place`, `swing-up`), its meaningful parts.
pub(crate) fn tag_stems(tag: &str) -> Vec<String> {
    let tag = tag.to_lowercase();
    let mut out = vec![stem(&tag)];
    if tag.contains(['-', '_', ' ']) {
        for part in tag.split(['-', '_', ' ']) {
            if part.len() >= 3 && !STOP_WORDS.contains(&part) {
                out.push(stem(part));
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stems_meet() {
        for (a, b) in [
            ("walking", "walk"),
            ("running", "run"),
            ("runs", "run"),
            ("hopping", "hop"),
            ("hops", "hop"),
            ("placed", "place"),
            ("placing", "place"),
            ("pushes", "push"),
            ("boxes", "box"),
            ("balancing", "balance"),
            ("stacked", "stack"),
            ("swimming", "swim"),
            ("lifts", "lift"),
            ("swinging", "swing"),
            ("fingers", "finger"),
            ("manipulating", "manipulation"),
        ] {
            assert!(
                stems_match(&stem(a), &stem(b)),
                "{a} / {b}: {} vs {}",
                stem(a),
                stem(b)
            );
        }
    }

    #[test]
    fn short_words_do_not_match_everything() {
        assert!(!stems_match(&stem("pen"), &stem("pendulum")));
        assert!(!stems_match(&stem("a"), &stem("arm")));
        assert!(!stems_match(&stem("run"), &stem("rubble")));
        assert!(stems_match(&stem("manipulate"), &stem("manipulation")));
    }

    #[test]
    fn words_split_compounds_and_punctuation() {
        assert_eq!(
            words("Pick-and-place: pick up the cube, and place it!"),
            vec!["pick", "place", "cube"]
        );
    }

    #[test]
    fn compound_tags_offer_their_parts() {
        let stems = tag_stems("swing-up");
        assert!(stems.contains(&"swing".to_string()));
        assert!(!stems.contains(&"up".to_string()));
    }
}
