//! Property tests of the loader: random bytes, truncated files and mutated
//! rows never panic; a refused file's error names the file and line.

use gyropath::import::parse;
use gyropath::signals::Signals;
use proptest::prelude::*;

/// A small valid log (the bundled sample's first rows).
fn sample() -> String {
    let text =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/data/sample-ride.csv"))
            .expect("sample");
    text.lines().take(400).collect::<Vec<_>>().join("\n") + "\n"
}

/// Load and derive; returns the error text if refused. Panics fail the property.
fn load(bytes: &[u8]) -> Option<String> {
    match parse(bytes, "fuzz.csv") {
        Ok(log) => Signals::from_log(&log).err().map(|e| e.to_string()),
        Err(e) => Some(e.to_string()),
    }
}

fn names_a_line(msg: &str) -> bool {
    // "fuzz.csv:LINE: ..." or "fuzz.csv: ..." for whole-file problems (no rows, no fix).
    msg.starts_with("fuzz.csv:")
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 400, ..ProptestConfig::default() })]

    #[test]
    fn random_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..2048)) {
        if let Some(msg) = load(&bytes) {
            prop_assert!(names_a_line(&msg), "{}", msg);
        }
    }

    #[test]
    fn truncated_files_never_panic(cut in 0usize..30_000) {
        let text = sample();
        let cut = cut.min(text.len());
        if let Some(msg) = load(&text.as_bytes()[..cut]) {
            prop_assert!(names_a_line(&msg), "{}", msg);
        }
    }

    #[test]
    fn mutated_fields_are_refused_with_their_line_or_loaded(
        row in 5usize..390,
        field in 0usize..10,
        junk in prop_oneof![
            Just(String::from("NaN")),
            Just(String::from("inf")),
            Just(String::from("-1e999")),
            Just(String::from("1,2")),
            Just(String::from("\"")),
            Just(String::new()),
            "[a-z0-9.+-]{1,8}",
        ],
    ) {
        let text = sample();
        let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
        let header = lines.iter().position(|l| !l.starts_with('#')).expect("header");
        let target = (header + 1 + row).min(lines.len() - 1);
        let mut fields: Vec<String> = lines[target].split(',').map(str::to_string).collect();
        let f = field % fields.len();
        fields[f] = junk;
        lines[target] = fields.join(",");
        let bytes = lines.join("\n").into_bytes();
        if let Some(msg) = load(&bytes) {
            prop_assert!(names_a_line(&msg), "{}", msg);
            // A refused data row names its own line (1-based in the file).
            if msg.contains("column") {
                let line = format!("fuzz.csv:{}:", target + 1);
                prop_assert!(msg.starts_with(&line) || msg.contains("time"), "{} (expected {})", msg, line);
            }
        }
    }
}
