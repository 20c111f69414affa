//! The range of every numeric command-line argument, checked as clap parses it: a value that is not a
//! finite number within its range is refused with the range in the error, before anything runs.

use softcontact_nodes::runtime::params::Shown;

/// A real number within [low, high] (`unit` is printed after the range).
pub fn real(low: f64, high: f64, unit: &'static str) -> impl Fn(&str) -> Result<f64, String> + Clone + Send + Sync {
    move |s: &str| {
        let v: f64 = s.trim().parse().map_err(|_| format!("`{s}` is not a number"))?;
        if v.is_finite() && v >= low && v <= high {
            Ok(v)
        } else {
            let (low, high) = (Shown(low), Shown(high));
            Err(format!("must be a finite number within [{low}, {high}]{unit}"))
        }
    }
}

/// A whole number within [low, high].
pub fn whole(low: u64, high: u64) -> impl Fn(&str) -> Result<u64, String> + Clone + Send + Sync {
    move |s: &str| {
        let v: u64 = s.trim().parse().map_err(|_| format!("`{s}` is not a whole number ≥ 0"))?;
        if v >= low && v <= high { Ok(v) } else { Err(format!("must be a whole number within [{low}, {high}]")) }
    }
}

/// The same as a `usize`.
pub fn count(low: usize, high: usize) -> impl Fn(&str) -> Result<usize, String> + Clone + Send + Sync {
    let parse = whole(low as u64, high as u64);
    move |s: &str| parse(s).map(|v| v as usize)
}

#[cfg(test)]
mod tests {
    use clap::{CommandFactory, Parser};

    /// Every argument of every subcommand that takes a number refuses what no command can use (the
    /// positional force of `softcontact force` is checked by the controller, with its limits, and
    /// below for non-finite values).
    #[test]
    fn every_numeric_argument_refuses_non_finite_huge_and_out_of_range_values() {
        let hostile = ["nan", "NaN", "inf", "-inf", "1e300", "-1e300", "18446744073709551616", "1e400", "x"];
        let mut checked = 0;
        let cli = crate::Cli::command();
        let mut commands: Vec<(Vec<String>, &clap::Command)> = vec![];
        for sub in cli.get_subcommands() {
            if sub.has_subcommands() {
                for inner in sub.get_subcommands() {
                    commands.push((vec![sub.get_name().into(), inner.get_name().into()], inner));
                }
            } else {
                commands.push((vec![sub.get_name().into()], sub));
            }
        }
        for (path, command) in commands {
            for arg in command.get_arguments() {
                let Some(long) = arg.get_long() else { continue };
                if !arg.get_action().takes_values() {
                    continue;
                }
                let argv = |value: &str| {
                    let mut argv: Vec<String> = vec!["softcontact".into()];
                    argv.extend(path.iter().cloned());
                    argv.push(format!("--{long}={value}"));
                    argv.extend(positional(&path));
                    argv
                };
                // A number argument: it takes some plain number, and no word.
                let takes = |value: &str| crate::Cli::try_parse_from(argv(value)).is_ok();
                let numeric = ["1", "0.5", "6", "0.01", "100", "0"].iter().any(|v| takes(v)) && !takes("abc");
                if !numeric {
                    continue;
                }
                for value in hostile {
                    let argv = argv(value);
                    let parsed = crate::Cli::try_parse_from(&argv);
                    assert!(parsed.is_err(), "{} was taken", argv.join(" "));
                    let error = parsed.err().unwrap().to_string();
                    assert!(error.contains(&format!("--{long}")), "{}: {error}", argv.join(" "));
                }
                checked += 1;
            }
        }
        assert!(checked >= 35, "{checked} numeric arguments checked");
    }

    fn positional(path: &[String]) -> Vec<String> {
        match path[0].as_str() {
            "identify" | "discrepancy" | "replay" => vec!["file.mcap".into()],
            "force" => vec!["10".into()],
            _ => vec![],
        }
    }

    #[test]
    fn the_incidents_of_the_adversary_are_refused_with_the_range() {
        for argv in [
            "softcontact climb --links 18446744073709551615",
            "softcontact climb --height 1e300",
            "softcontact climb --step 1e-300",
            "softcontact record --duration nan",
            "softcontact identify f.mcap --onset 1e-300",
            "softcontact force nan",
            "softcontact force 1e300",
            "softcontact force -inf",
        ] {
            let parsed = crate::Cli::try_parse_from(argv.split(' '));
            let error = parsed.err().unwrap_or_else(|| panic!("{argv} was taken")).to_string();
            assert!(error.contains("within") || error.contains("not a"), "{argv}: {error}");
            assert!(error.len() < 400, "{argv}: the range printed in full: {error}");
        }
    }
}
