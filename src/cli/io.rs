//! The standard streams, written so that a failing one (stderr to `/dev/full`, a closed
//! pipe) never panics, as `eprintln!` and `println!` do.

use std::io::Write as _;

/// A line on stderr: progress and messages. A failure to write it is ignored: the run's
/// work and its exit status do not depend on whether anyone reads its progress.
pub fn say(line: &str) {
    let mut stderr = std::io::stderr().lock();
    let _ = writeln!(stderr, "{line}");
}

/// `text` on stdout, where it is the product (`--list-adapters`, `compare`). A reader that
/// closed the pipe early (`| head`) made its choice and is not an error; any other failure
/// (a full disk) is.
pub fn print_stdout(text: &str) -> std::io::Result<()> {
    let mut stdout = std::io::stdout().lock();
    match stdout.write_all(text.as_bytes()).and_then(|()| stdout.flush()) {
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Ok(()),
        result => result,
    }
}

/// An error and its causes, each said once: `Error::Io` prints its OS error and also
/// hands it on as its source, which anyhow's `{:#}` would print a second time.
pub fn describe(error: &anyhow::Error) -> String {
    let mut text = error.to_string();
    for cause in error.chain().skip(1) {
        let cause = cause.to_string();
        if !text.contains(&cause) {
            text.push_str(": ");
            text.push_str(&cause);
        }
    }
    text
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_cause_is_said_once() {
        let os = std::io::Error::new(std::io::ErrorKind::NotFound, "No such file or directory (os error 2)");
        let e = anyhow::Error::new(firstshot::Error::Io { path: "a/b.exr".into(), source: os });
        assert_eq!(describe(&e), "a/b.exr: No such file or directory (os error 2)");
        let e = anyhow::anyhow!("inner").context("outer");
        assert_eq!(describe(&e), "outer: inner");
    }
}
