//! The command-line reference as Markdown, generated from the clap definitions (`iuq
//! markdown-help`, hidden): the documentation site's CLI page is this output, so that it cannot
//! drift from the program.

use std::fmt::Write;

use clap::{Arg, ArgAction, Command};

/// The whole reference of `root`: every command and subcommand with its usage, arguments and
/// options, their help, defaults and possible values.
pub fn markdown_help(root: &Command) -> String {
    let mut out = String::new();
    let _ = writeln!(out, "# Command-line reference\n");
    let _ = writeln!(
        out,
        "Generated from `{} markdown-help` (the program's own definitions); `{} <command> --help` prints the same for one command.\n",
        root.get_name(),
        root.get_name()
    );
    let mut root = root.clone();
    root.build();
    let _ = writeln!(out, "## Commands\n");
    for sub in visible_subcommands(&root) {
        let _ = writeln!(
            out,
            "- [`{} {}`](#{}): {}",
            root.get_name(),
            sub.get_name(),
            anchor(&format!("{} {}", root.get_name(), sub.get_name())),
            first_line(sub)
        );
    }
    out.push('\n');
    write_command(&mut out, &root, root.get_name(), 2);
    out
}

fn visible_subcommands(command: &Command) -> impl Iterator<Item = &Command> {
    command
        .get_subcommands()
        .filter(|c| !c.is_hide_set() && c.get_name() != "help")
}

fn first_line(command: &Command) -> String {
    command
        .get_about()
        .map(|a| a.to_string().lines().next().unwrap_or_default().to_string())
        .unwrap_or_default()
}

/// The anchor mdBook gives a heading: lower case, spaces as hyphens, other punctuation dropped.
fn anchor(heading: &str) -> String {
    heading
        .to_lowercase()
        .chars()
        .filter_map(|c| match c {
            ' ' => Some('-'),
            c if c.is_alphanumeric() || c == '-' || c == '_' => Some(c),
            _ => None,
        })
        .collect()
}

fn write_command(out: &mut String, command: &Command, path: &str, depth: usize) {
    let hashes = "#".repeat(depth.min(6));
    let _ = writeln!(out, "{hashes} {path}\n");
    if let Some(about) = command.get_long_about().or(command.get_about()) {
        let _ = writeln!(out, "{about}\n");
    }
    let mut usage_command = command.clone();
    let usage = usage_command.render_usage().to_string();
    let usage = usage.trim_start_matches("Usage: ").trim();
    // A built command's usage names its whole path already; an unbuilt one only its own name.
    let usage = if usage.starts_with(path) {
        usage.to_string()
    } else {
        match usage.split_once(' ') {
            Some((_, rest)) => format!("{path} {rest}"),
            None => path.to_string(),
        }
    };
    let _ = writeln!(out, "```text\n{usage}\n```\n");
    let arguments: Vec<&Arg> = command
        .get_arguments()
        .filter(|a| !a.is_hide_set() && a.get_id() != "help" && a.get_id() != "version")
        .collect();
    let (positionals, options): (Vec<&Arg>, Vec<&Arg>) =
        arguments.into_iter().partition(|a| a.is_positional());
    if !positionals.is_empty() {
        let _ = writeln!(out, "Arguments:\n");
        for arg in positionals {
            let name = arg.get_value_names().and_then(|v| v.first()).map_or_else(
                || arg.get_id().to_string().to_uppercase(),
                |n| n.to_string(),
            );
            let _ = writeln!(out, "- `{name}`{}", describe(arg));
        }
        out.push('\n');
    }
    if !options.is_empty() {
        let _ = writeln!(out, "Options:\n");
        for arg in options {
            let _ = writeln!(out, "- `{}`{}", option_form(arg), describe(arg));
        }
        out.push('\n');
    }
    let subcommands: Vec<&Command> = visible_subcommands(command).collect();
    if !subcommands.is_empty() && path.contains(' ') {
        let _ = writeln!(out, "Subcommands:\n");
        for sub in &subcommands {
            let _ = writeln!(out, "- `{}`: {}", sub.get_name(), first_line(sub));
        }
        out.push('\n');
    }
    // The root's commands are sections of their own (as deep as the root), their subcommands
    // one level deeper.
    let child_depth = if path.contains(' ') { depth + 1 } else { depth };
    for sub in subcommands {
        write_command(out, sub, &format!("{path} {}", sub.get_name()), child_depth);
    }
}

fn option_form(arg: &Arg) -> String {
    let mut names = Vec::new();
    if let Some(short) = arg.get_short() {
        names.push(format!("-{short}"));
    }
    if let Some(long) = arg.get_long() {
        names.push(format!("--{long}"));
    }
    let mut form = names.join(", ");
    let takes_value = !matches!(
        arg.get_action(),
        ArgAction::SetTrue | ArgAction::SetFalse | ArgAction::Count | ArgAction::Help
    );
    if takes_value {
        let value = arg.get_value_names().and_then(|v| v.first()).map_or_else(
            || arg.get_id().to_string().to_uppercase(),
            |n| n.to_string(),
        );
        let _ = write!(form, " <{value}>");
    }
    form
}

fn describe(arg: &Arg) -> String {
    let mut text = String::new();
    if let Some(help) = arg.get_long_help().or(arg.get_help()) {
        let help = help.to_string().replace('\n', " ");
        let _ = write!(text, ": {help}");
    }
    let possible: Vec<String> = arg
        .get_possible_values()
        .iter()
        .filter(|v| !v.is_hide_set())
        .map(|v| format!("`{}`", v.get_name()))
        .collect();
    if !possible.is_empty() {
        let _ = write!(text, " (one of {})", possible.join(", "));
    }
    let defaults: Vec<String> = arg
        .get_default_values()
        .iter()
        .map(|v| format!("`{}`", v.to_string_lossy()))
        .collect();
    if !defaults.is_empty() {
        let _ = write!(text, " (default {})", defaults.join(", "));
    }
    if arg.is_required_set() {
        text.push_str(" (required)");
    }
    text
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;

    #[test]
    fn the_reference_holds_every_visible_command_and_option() {
        let root = crate::Cli::command();
        let text = markdown_help(&root);
        for sub in visible_subcommands(&root) {
            assert!(
                text.contains(&format!("## iuq {}\n", sub.get_name())),
                "{}",
                sub.get_name()
            );
        }
        assert!(text.contains("`--json`"), "the global option");
        assert!(text.contains("### iuq gp fit\n"), "a nested subcommand");
        assert!(
            !text.contains("markdown-help\n\n```text"),
            "the hidden command itself"
        );
    }
}
