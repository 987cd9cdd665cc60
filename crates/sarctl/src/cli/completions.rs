//! `sarctl completions bash|zsh|fish`: the shell's completions of `sarctl`'s
//! command line, on stdout.

/// The shells `sarctl completions` writes for. (The variants carry no doc
/// comment: clap would print it in `sarctl completions --help`.)
#[allow(missing_docs)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum CompletionShell {
    Bash,
    Zsh,
    Fish,
}

/// Writes the completions of `cmd` (`sarctl`'s whole command line) for `shell`.
pub fn run(mut cmd: clap::Command, shell: CompletionShell) -> Result<(), String> {
    let shell = match shell {
        CompletionShell::Bash => clap_complete::Shell::Bash,
        CompletionShell::Zsh => clap_complete::Shell::Zsh,
        CompletionShell::Fish => clap_complete::Shell::Fish,
    };
    clap_complete::generate(shell, &mut cmd, "sarctl", &mut std::io::stdout());
    Ok(())
}
