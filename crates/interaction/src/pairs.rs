//! Which clips are the two partners of one interaction. One rule for every
//! caller (the pipeline's plan, the service's upload check, the CLI's folders
//! of pairs), so a pair the CLI accepts is a pair the service plans.

/// Two-person pairs among clip names: `<stem>_A` with `<stem>_B` (the CMU
/// pairs' naming; `_a` / `_b` too). Returns `(stem, a, b)` sorted by stem.
pub fn pairs(names: &[String]) -> Vec<(String, String, String)> {
    let mut out = Vec::new();
    for a in names {
        let Some(stem) = a.strip_suffix("_A").or_else(|| a.strip_suffix("_a")) else {
            continue;
        };
        if let Some(b) = names
            .iter()
            .find(|b| b.as_str() == format!("{stem}_B") || b.as_str() == format!("{stem}_b"))
        {
            out.push((stem.to_string(), a.clone(), b.clone()));
        }
    }
    out.sort();
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(list: &[&str]) -> Vec<String> {
        list.iter().map(|s| s.to_string()).collect()
    }

    #[test]
    fn partners_pair_by_stem_in_either_case() {
        let found = pairs(&names(&[
            "walk_B", "walk_A", "hug_a", "hug_b", "alone_A", "x_B", "kick",
        ]));
        assert_eq!(
            found,
            vec![
                ("hug".into(), "hug_a".into(), "hug_b".into()),
                ("walk".into(), "walk_A".into(), "walk_B".into()),
            ]
        );
    }

    #[test]
    fn no_pairs_among_unrelated_names() {
        assert!(pairs(&names(&["a", "b", "A_", "_A"])).is_empty());
    }
}
