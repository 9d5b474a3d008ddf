//! The README's configuration table names every key the config structs accept, and every
//! command-line option has help text.

use std::process::Command;

/// The README row for `[section]`, as text.
fn readme_row(readme: &str, section: &str) -> String {
    let head = format!("| `[{section}]` |");
    readme
        .lines()
        .find(|l| l.starts_with(&head))
        .unwrap_or_else(|| panic!("README: no row for [{section}] in the key table"))
        .to_string()
}

#[test]
fn the_readme_key_table_names_every_config_key() {
    let readme =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/README.md")).unwrap();
    let cfg = serde_json::to_value(impactcam::config::Config::default_config()).unwrap();
    let mut missing = Vec::new();
    for (section, table) in cfg.as_object().unwrap() {
        if section == "geometry" {
            continue; // documented by the example above the table, key by key
        }
        let row = readme_row(&readme, section);
        for key in table.as_object().unwrap().keys() {
            if !row.contains(&format!("`{key}`")) && !row.contains(&format!("`[{section}.{key}]`"))
            {
                missing.push(format!("[{section}] {key}"));
            }
        }
    }
    assert!(missing.is_empty(), "README key table lacks: {missing:?}");
}

/// Subcommands, as argument lists, whose options and arguments must all have help text.
const COMMANDS: &[&[&str]] = &[
    &["run"],
    &["capture"],
    &["replay"],
    &["analyze"],
    &["serve"],
    &["sweep"],
    &["fit"],
    &["export"],
    &["devices"],
    &["config", "check"],
    &["config", "default"],
    &["bench", "capture"],
    &["bench", "soak"],
    &["bench", "relay"],
    &["bench", "accuracy"],
    &["bench", "validation"],
    &["bench", "rigs"],
    &["bench", "analysis"],
];

#[test]
fn every_option_has_help_text() {
    let mut bare = Vec::new();
    for args in COMMANDS {
        let out = Command::new(env!("CARGO_BIN_EXE_impactcam"))
            .args(*args)
            .arg("--help")
            .output()
            .unwrap();
        assert!(out.status.success(), "{args:?} --help");
        let text = String::from_utf8_lossy(&out.stdout);
        let lines: Vec<&str> = text.lines().collect();
        let mut in_list = false;
        for (k, line) in lines.iter().enumerate() {
            if *line == "Options:" || *line == "Arguments:" {
                in_list = true;
                continue;
            }
            if line.is_empty() {
                in_list = false;
                continue;
            }
            // An entry starts with its name ("-x, --name <NAME>", "[PATH]"); its help follows
            // after two spaces on the same line, or (when clap wraps) on the next, indented.
            let entry = line.trim_start();
            let is_entry = in_list && entry.starts_with(['-', '[', '<']);
            if is_entry && !entry.contains("  ") {
                let next_is_help = lines
                    .get(k + 1)
                    .is_some_and(|n| n.starts_with("        ") && !n.trim_start().starts_with('-'));
                if !next_is_help {
                    bare.push(format!("{}: {entry}", args.join(" ")));
                }
            }
        }
    }
    assert!(bare.is_empty(), "options without help text: {bare:#?}");
}
