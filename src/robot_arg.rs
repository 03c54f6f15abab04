//! The robot option of the `rbss` subcommands (`--model NAME` or `--model-file PATH`), in a
//! module of its own: the argument parser ([`crate::cli`]) and the studies' subcommands
//! ([`crate::bench`]) both take it.

/// The robot a subcommand names: `--model NAME` (compiled into the command) or
/// `--model-file PATH` (generated, compiled and cached on first use; see
/// [`crate::model_file`]).
#[derive(clap::Args, Debug, Clone)]
pub struct RobotArg {
    /// Robot name (see `rbss list`).
    #[arg(
        long,
        required_unless_present = "model_file",
        conflicts_with = "model_file"
    )]
    pub model: Option<String>,
    /// A model file (models/*.toml): generated and compiled into a library on first use,
    /// cached (in $RBSS_CACHE, else $XDG_CACHE_HOME/rbss or ~/.cache/rbss) and loaded; needs
    /// cargo and the rbss sources this command was built from.
    #[arg(long, value_name = "PATH")]
    pub model_file: Option<String>,
}

impl RobotArg {
    /// The `--model` name (an error with `--model-file`, which `main` handles before).
    pub fn name(&self) -> Result<&str, String> {
        self.model
            .as_deref()
            .ok_or_else(|| "--model-file is run by the robot's library".to_string())
    }
}
