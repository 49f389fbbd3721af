//! gyropath command line (the app comes later; without arguments this prints usage).

mod cli;

use clap::{CommandFactory, Parser};

fn main() {
    let args = cli::Cli::parse();
    let result = match &args.command {
        Some(cli::Command::Fit(a)) => cli::fit(a),
        Some(cli::Command::Simulate(a)) => cli::simulate(a),
        None => {
            let _ = cli::Cli::command().print_help();
            println!();
            return;
        }
    };
    if let Err(e) = result {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}
