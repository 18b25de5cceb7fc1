//! The help teaches: every command's `--help` has its description and examples that parse,
//! and the README's command table and shell examples match the command line.

use super::cli_command;

/// Every command and nested command (not clap's `help`), with its path of names.
fn commands() -> Vec<(Vec<String>, clap::Command)> {
    fn walk(path: Vec<String>, c: &clap::Command, out: &mut Vec<(Vec<String>, clap::Command)>) {
        for s in c.get_subcommands().filter(|s| s.get_name() != "help") {
            let mut p = path.clone();
            p.push(s.get_name().to_string());
            out.push((p.clone(), s.clone()));
            walk(p, s, out);
        }
    }
    let mut out = Vec::new();
    walk(Vec::new(), &cli_command(), &mut out);
    out
}

/// The `drbokeh ...` command lines of a text: lines starting with `drbokeh ` (after
/// indentation), with `\` continuation lines joined.
fn command_lines(text: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut pending: Option<String> = None;
    for line in text.lines() {
        // A shell comment ends the command.
        let t = line.split(" #").next().unwrap_or("").trim();
        if let Some(mut p) = pending.take() {
            p.push(' ');
            p.push_str(t.trim_end_matches('\\').trim());
            if t.ends_with('\\') {
                pending = Some(p);
            } else {
                out.push(p);
            }
        } else if t.starts_with("drbokeh ") {
            let body = t.trim_end_matches('\\').trim().to_string();
            if t.ends_with('\\') {
                pending = Some(body);
            } else {
                out.push(body);
            }
        }
    }
    out.extend(pending);
    out
}

/// The examples of a long help: the command lines after its "Examples" heading, up to the
/// first blank line.
fn examples(help: &str) -> Vec<String> {
    let help = format!("\n{help}");
    let Some(start) = help.find("\nExamples") else {
        return Vec::new();
    };
    let rest = &help[start + 1..];
    let rest = &rest[rest.find('\n').map_or(rest.len(), |i| i + 1)..];
    let block = rest.split("\n\n").next().unwrap_or("");
    command_lines(block)
}

/// Parses a command line as `main` does; `Err` with clap's message when it does not.
fn parse(line: &str) -> Result<(), String> {
    let words: Vec<&str> = line.split_whitespace().collect();
    match cli_command().try_get_matches_from(words) {
        Ok(_) => Ok(()),
        // `drbokeh render --help` is a fine example.
        Err(e) if e.kind() == clap::error::ErrorKind::DisplayHelp => Ok(()),
        Err(e) => Err(format!("`{line}` does not parse: {e}")),
    }
}

#[test]
fn every_command_help_has_a_description_and_examples_that_parse() {
    for (path, c) in commands() {
        let name = path.join(" ");
        let help = c.clone().term_width(100).render_long_help().to_string();
        let short = c.clone().term_width(100).render_help().to_string();
        // --help is the long form (description and examples), -h the short one.
        let about = c.get_about().map(|a| a.to_string()).unwrap_or_default();
        assert!(!about.is_empty(), "drbokeh {name} has no summary line");
        assert!(help.starts_with(&about), "drbokeh {name}: {help}");
        assert!(
            c.get_long_about().is_some() && !short.contains("Examples"),
            "drbokeh {name}: --help has no long description, or -h is not short"
        );
        let ex = examples(&help);
        assert!(
            ex.len() >= 2,
            "drbokeh {name} --help has fewer than two examples: {ex:?}\n{help}"
        );
        for line in &ex {
            parse(line).unwrap();
        }
        // At least one example runs this very command.
        let own = format!("drbokeh {name} ");
        assert!(
            ex.iter().any(|l| l.starts_with(&own)),
            "no example of drbokeh {name} in {ex:?}"
        );
    }
    // The top-level help too.
    let top = cli_command().term_width(100).render_long_help().to_string();
    let ex = examples(&top);
    assert!(ex.len() >= 2, "{top}");
    for line in &ex {
        parse(line).unwrap();
    }
}

#[test]
fn the_parser_of_examples_would_catch_a_wrapped_or_wrong_example() {
    let help = "Examples:\n  drbokeh render --demo \\\n      -o a.png\n  drbokeh render --demo\n  -o b.png\n\nMore";
    let ex = examples(help);
    assert_eq!(
        ex,
        ["drbokeh render --demo -o a.png", "drbokeh render --demo"]
    );
    assert!(parse(&ex[0]).is_ok());
    // A wrapped line loses its --output: it no longer parses.
    assert!(parse(&ex[1]).is_err());
    assert!(parse("drbokeh render --demo --no-such-flag -o x.png").is_err());
}

#[test]
fn every_command_that_writes_takes_dash_o_and_output_and_out_still_works() {
    for (path, c) in commands() {
        let Some(output) = c
            .get_arguments()
            .find(|a| a.get_id() == "output" || a.get_id() == "out")
        else {
            continue;
        };
        let name = path.join(" ");
        assert_eq!(output.get_long(), Some("output"), "drbokeh {name}");
        assert_eq!(output.get_short(), Some('o'), "drbokeh {name}");
    }
    for line in [
        "drbokeh trace examples/scene.json --out t",
        "drbokeh benchmark make --out b",
        "drbokeh eval --benchmark b --out r",
        "drbokeh gallery --images i --out g",
        "drbokeh dfd-eval --synthetic --out r",
        "drbokeh dfd-eval --synthetic --layers drbokeh -o r",
        "drbokeh dfd --all-in-focus a.png --defocused b.png --focus 1 --blur 3 --layer gausspsf -o d.png",
    ] {
        parse(line).unwrap();
    }
}

/// The first column of the README's command table ("Everything else it does"): the
/// commands it names, as paths of subcommand names.
fn readme_table_commands(readme: &str) -> Vec<Vec<String>> {
    let mut out = Vec::new();
    let mut in_table = false;
    for line in readme.lines() {
        if line.starts_with("| command |") {
            in_table = true;
            continue;
        }
        if in_table {
            if !line.starts_with('|') {
                break;
            }
            let first = line.split('|').nth(1).unwrap_or("");
            for cell in first.split('`').skip(1).step_by(2) {
                if let Some(rest) = cell.strip_prefix("drbokeh ") {
                    out.push(rest.split_whitespace().map(String::from).collect());
                }
            }
        }
    }
    out
}

fn readme() -> String {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../README.md");
    std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{path}: {e}"))
}

#[test]
fn readme_command_table_lists_exactly_the_commands() {
    let readme = readme();
    let table = readme_table_commands(&readme);
    assert!(!table.is_empty(), "no command table in README.md");
    let leaves: Vec<Vec<String>> = commands()
        .into_iter()
        .filter(|(_, c)| !c.has_subcommands())
        .map(|(p, _)| p)
        .collect();
    for c in &leaves {
        assert!(
            table.contains(c),
            "README's command table lacks drbokeh {}",
            c.join(" ")
        );
    }
    for t in &table {
        assert!(
            leaves.contains(t),
            "README's command table names drbokeh {}, which is no command",
            t.join(" ")
        );
    }
}

#[test]
fn readme_shell_examples_parse() {
    let readme = readme();
    let mut blocks = Vec::new();
    let mut current: Option<String> = None;
    for line in readme.lines() {
        match (&mut current, line.trim_start().starts_with("```")) {
            (None, true) if line.trim_start().starts_with("```sh") => current = Some(String::new()),
            (Some(_), true) => blocks.extend(current.take()),
            (Some(b), false) => {
                b.push_str(line);
                b.push('\n');
            }
            _ => {}
        }
    }
    let lines: Vec<String> = blocks.iter().flat_map(|b| command_lines(b)).collect();
    assert!(lines.len() >= 5, "{lines:?}");
    for line in &lines {
        parse(line).unwrap();
    }
}
