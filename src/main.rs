//! gyropath: the app without arguments (or `gyropath open RIDE.csv`), else the command line.

mod cli;

use clap::Parser;

fn main() {
    restore_sigpipe();
    let args = cli::Cli::parse();
    let result = match &args.command {
        Some(cli::Command::Fit(a)) => cli::fit(a),
        Some(cli::Command::Simulate(a)) => cli::simulate(a),
        Some(cli::Command::Diagnose(a)) => cli::diagnose(a),
        Some(cli::Command::Explain(a)) => cli::explain(a),
        Some(cli::Command::Import(a)) => cli::import(a),
        Some(cli::Command::Check(a)) => cli::check(a),
        Some(cli::Command::Open(a)) => open(a),
        None => open_app(None, None),
    };
    if let Err(e) = result {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}

/// `gyropath open`: the ride (or the sample) and a reference track. A
/// reference that is not there fails here, before a window opens.
fn open(a: &cli::OpenArgs) -> anyhow::Result<()> {
    if let Some(r) = &a.reference
        && !r.exists()
    {
        anyhow::bail!("reference track {}: no such file or folder", r.display());
    }
    let ride = match &a.ride {
        Some(ride) => Some((ride.clone(), a.source.options()?)),
        None => None,
    };
    open_app(ride, a.reference.clone())
}

#[cfg(feature = "app")]
fn open_app(
    ride: Option<(std::path::PathBuf, gyropath::import::ImportOptions)>,
    reference: Option<std::path::PathBuf>,
) -> anyhow::Result<()> {
    gyropath::app::run(ride, reference)
        .map_err(|e| anyhow::anyhow!("cannot open the app window: {e}"))
}

#[cfg(not(feature = "app"))]
fn open_app(
    _ride: Option<(std::path::PathBuf, gyropath::import::ImportOptions)>,
    _reference: Option<std::path::PathBuf>,
) -> anyhow::Result<()> {
    use clap::CommandFactory;
    let _ = cli::Cli::command().print_help();
    println!();
    anyhow::bail!("this build has no app (built without the `app` feature); use a subcommand")
}

/// Rust ignores SIGPIPE, so a write to a closed pipe (`gyropath explain RIDE
/// | head -2`) is an error that `println!` turns into a panic. The default
/// disposition ends the process quietly when the reader has gone, as every
/// Unix tool does.
#[cfg(unix)]
fn restore_sigpipe() {
    // SAFETY: called first thing in main, before any other thread exists;
    // SIG_DFL is a valid disposition for SIGPIPE.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}

#[cfg(not(unix))]
fn restore_sigpipe() {}
