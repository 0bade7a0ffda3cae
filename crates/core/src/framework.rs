//! Framework names and their aliases (`gym` is `gymnasium`, `mjcf` is `custom_mjcf`, ...).

/// A framework an adapter can serve, with the other names users write for it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Framework {
    /// The canonical name, as used in registry entries.
    pub name: &'static str,
    /// Other accepted spellings.
    pub aliases: &'static [&'static str],
}

/// Every framework envhub knows by name. User adapters may add their own names.
pub const FRAMEWORKS: &[Framework] = &[
    Framework {
        name: "gymnasium",
        aliases: &["gym"],
    },
    Framework {
        name: "custom_mjcf",
        aliases: &["mjcf", "urdf", "custom"],
    },
    Framework {
        name: "rapier",
        aliases: &["rapier3d"],
    },
    Framework {
        name: "maniskill",
        aliases: &["mani_skill", "sapien"],
    },
    Framework {
        name: "libero",
        aliases: &[],
    },
    Framework {
        name: "isaac_lab",
        aliases: &["isaaclab", "isaac_gym"],
    },
];

/// The canonical name of a framework or alias (case-insensitive); `None` if unknown.
pub fn canonical_framework(name: &str) -> Option<&'static str> {
    let name = name.trim().to_lowercase();
    FRAMEWORKS
        .iter()
        .find(|f| f.name == name || f.aliases.contains(&name.as_str()))
        .map(|f| f.name)
}

#[cfg(test)]
mod tests {
    use super::canonical_framework;

    #[test]
    fn resolves_aliases() {
        assert_eq!(canonical_framework("gym"), Some("gymnasium"));
        assert_eq!(canonical_framework("URDF"), Some("custom_mjcf"));
        assert_eq!(canonical_framework("isaac_gym"), Some("isaac_lab"));
        assert_eq!(canonical_framework("sapien"), Some("maniskill"));
        assert_eq!(canonical_framework("libero"), Some("libero"));
        assert_eq!(canonical_framework("rapier3d"), Some("rapier"));
        assert_eq!(canonical_framework("bullet"), None);
    }
}
