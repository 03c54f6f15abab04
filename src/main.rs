//! `rbss`: solve a generated robot's kinematic problems from the command line.
//!
//! ```text
//! rbss list
//! rbss ik   --model stewart_6ups --pose 0.1,0,0.94,0.1,0,0
//! rbss ik   --model five_bar --pose 0.05,0.32 --rates 0.1,-0.2 --json
//! rbss fk   --model stewart_6ups --q 0.93,0.98,1.04,0.98,0.96,0.97
//! rbss fk   --model five_bar --q 2.0,1.2 --max-passive-change 0.5
//! rbss eval --model stewart_6ups --states states.json > kernels.json
//! rbss inverse-dynamics --model five_bar --trajectory models/trajectories/five_bar_figure_eight.csv --csv u.csv
//! rbss roundtrip --model ur5 --out DIR          # any robot, along models/trajectories/NAME.toml
//! ```
//!
//! A command's results go to stdout when it has finished; progress and errors to stderr. A
//! closed stdout (`rbss list | head -c1`) ends the command quietly with status 0, as when the
//! reader had read everything: the reader chose to stop. Any other failure to write stdout is
//! an error (status 1). A closed stderr drops the messages.

use std::io::Write as _;
use std::process::ExitCode;

use clap::Parser;
use rbss::cli::{Cli, finish, run};

/// `eprintln!` that drops the line when stderr is closed instead of panicking.
macro_rules! say {
    ($($t:tt)*) => {{
        let _ = writeln!(std::io::stderr().lock(), $($t)*);
    }};
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    // A robot from a model file: its library runs the subcommand (parsing the same arguments).
    if let Some(path) = cli.cmd.model_file().map(str::to_string) {
        let args: Vec<String> = std::env::args().collect();
        let variant = if cli.cmd.is_study() {
            rbss::model_file::Variant::Studies
        } else if cli.cmd.needs_derivatives() {
            rbss::model_file::Variant::Full
        } else {
            rbss::model_file::Variant::Plain
        };
        return match rbss::model_file::run(&path, variant, &args) {
            Ok(code) => ExitCode::from(code),
            Err(e) => {
                say!("rbss: error: {e}");
                ExitCode::FAILURE
            }
        };
    }
    let mut stdout = String::new();
    let result = run(cli, &mut stdout);
    ExitCode::from(finish(result, &stdout))
}
