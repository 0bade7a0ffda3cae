//! What a hub lets remote clients do.

/// What a hub lets remote clients do.
#[derive(Clone, Debug, Default)]
pub struct ServePolicy {
    /// Envs this hub hosts for remote clients at once, over all sessions (`None`: no limit).
    pub max_envs: Option<usize>,
    /// Worker processes it runs for remote clients at once (`None`: no limit).
    pub max_workers: Option<usize>,
    /// Let remote clients name files on this hub (`asset_path`, `xml_file`, ...).
    pub allow_remote_files: bool,
    /// Build the Python environment an entry needs for a remote client when it is not
    /// provisioned yet (installing packages is the operator's decision).
    pub allow_provision: bool,
}
