//! The documentation's links: every relative link in the repository's Markdown files names a
//! file that exists and, with a `#fragment`, a heading of that file (by GitHub's rule for
//! heading anchors). The docs are long and cross-linked (docs/PERFORMANCE.md alone has
//! hundreds of links into its own sections), and a user has only the repository: a renamed
//! section must not leave links pointing nowhere.

use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};

/// GitHub's anchor for a heading's text: lower case, every character but letters, digits,
/// spaces, hyphens and underscores dropped (backticks, apostrophes, commas, colons,
/// parentheses), spaces made hyphens.
fn anchor(heading: &str) -> String {
    heading
        .trim()
        .to_lowercase()
        .chars()
        .filter(|c| c.is_alphanumeric() || matches!(c, ' ' | '-' | '_'))
        .map(|c| if c == ' ' { '-' } else { c })
        .collect()
}

/// The text outside fenced code blocks (where `[a](b)` and `# x` are code, not Markdown).
fn prose(text: &str) -> Vec<&str> {
    let mut fenced = false;
    text.lines()
        .filter(|line| {
            if line.trim_start().starts_with("```") {
                fenced = !fenced;
                return false;
            }
            !fenced
        })
        .collect()
}

/// The anchors of a file's headings; a repeated heading's later anchors get -1, -2, ...
fn anchors(text: &str) -> HashSet<String> {
    let mut seen: HashMap<String, u32> = HashMap::new();
    let mut out = HashSet::new();
    for line in prose(text) {
        let hashes = line.chars().take_while(|&c| c == '#').count();
        if !(1..=6).contains(&hashes) || !line[hashes..].starts_with(' ') {
            continue;
        }
        let a = anchor(&line[hashes + 1..]);
        let n = seen.entry(a.clone()).or_insert(0);
        out.insert(if *n == 0 { a.clone() } else { format!("{a}-{n}") });
        *n += 1;
    }
    out
}

/// The link targets `](target)` of a file's prose (inline code spans left out).
fn links(text: &str) -> Vec<String> {
    let mut out = Vec::new();
    for line in prose(text) {
        // Inline code spans: the odd-numbered pieces between backticks.
        for (k, piece) in line.split('`').enumerate() {
            if k % 2 == 1 {
                continue;
            }
            let mut rest = piece;
            while let Some(at) = rest.find("](") {
                rest = &rest[at + 2..];
                let end = rest.find(|c: char| c == ')' || c.is_whitespace()).unwrap_or(rest.len());
                out.push(rest[..end].to_string());
            }
        }
    }
    out
}

fn markdown_files(root: &Path) -> Vec<PathBuf> {
    let mut files = Vec::new();
    let mut folders = vec![root.to_path_buf()];
    while let Some(folder) = folders.pop() {
        for entry in std::fs::read_dir(&folder).unwrap() {
            let path = entry.unwrap().path();
            let name = path.file_name().unwrap().to_string_lossy().to_string();
            if path.is_dir() {
                if !name.starts_with('.') && name != "target" && name != "shared" {
                    folders.push(path);
                }
            } else if name.ends_with(".md") {
                files.push(path);
            }
        }
    }
    files.sort();
    files
}

#[test]
fn test01_every_relative_link_reaches_its_file_and_heading() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let files = markdown_files(root);
    assert!(files.iter().any(|f| f.ends_with("docs/PERFORMANCE.md")), "{files:?}");
    let mut headings: HashMap<PathBuf, HashSet<String>> = HashMap::new();
    let mut broken = Vec::new();
    let mut checked = 0;
    for file in &files {
        let text = std::fs::read_to_string(file).unwrap();
        for target in links(&text) {
            if target.contains("://") || target.starts_with("mailto:") {
                continue;
            }
            let (path, fragment) = target.split_once('#').unwrap_or((&target, ""));
            let resolved = if path.is_empty() { file.clone() } else { file.parent().unwrap().join(path) };
            checked += 1;
            if !resolved.exists() {
                broken.push(format!("{}: {target}: no such file", file.display()));
                continue;
            }
            if fragment.is_empty() || resolved.extension().is_none_or(|e| e != "md") {
                continue;
            }
            let known = headings
                .entry(resolved.clone())
                .or_insert_with(|| anchors(&std::fs::read_to_string(&resolved).unwrap()));
            if !known.contains(fragment) {
                broken.push(format!("{}: {target}: no heading with that anchor", file.display()));
            }
        }
    }
    assert!(broken.is_empty(), "{} broken links of {checked}:\n{}", broken.len(), broken.join("\n"));
    assert!(checked > 100, "only {checked} links found: is the parser reading the docs?");
}

/// The anchor rule on headings of the kinds the docs use.
#[test]
fn test02_anchors_follow_githubs_rule() {
    assert_eq!(anchor("The targets' history"), "the-targets-history");
    assert_eq!(
        anchor("Where Sierpinski's start goes, a cheaper first-shot reduction (2026-11-30, 13:10-14:35 UTC)"),
        "where-sierpinskis-start-goes-a-cheaper-first-shot-reduction-2026-11-30-1310-1435-utc"
    );
    assert_eq!(
        anchor("Peers on the GPU: firstshot (Vulkan) against Mitsuba 3 `cuda_ad_rgb`"),
        "peers-on-the-gpu-firstshot-vulkan-against-mitsuba-3-cuda_ad_rgb"
    );
    let repeated = anchors("# Notes\ntext\n## Notes\n```\n# not a heading\n```\n### Notes\n");
    assert_eq!(repeated, HashSet::from(["notes".to_string(), "notes-1".to_string(), "notes-2".to_string()]));
    assert_eq!(links("see [a](x.md#y) and `[b](not/a/link)` and [c](#z)"), vec!["x.md#y", "#z"]);
}
