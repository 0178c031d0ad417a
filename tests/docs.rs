//! The documentation cannot rot: every relative link in README.md, CONTRIBUTING.md, docs/ and the
//! model cards names a file that exists, every `#anchor` a heading of its file, and every
//! repository path written in backticks exists. They speak of the project as it is: no work-log
//! words ("session", "issue N"), and the README and model cards stay short.
//!
//! Written here rather than with lychee: lychee's offline mode is a binary download that
//! `make test` cannot fetch, and these checks are a page of code.
use std::collections::HashMap;
use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The documents checked, relative to the repository root.
fn documents() -> Vec<PathBuf> {
    let mut docs = vec![PathBuf::from("README.md"), PathBuf::from("CONTRIBUTING.md")];
    let mut stack = vec![root().join("docs")];
    while let Some(dir) = stack.pop() {
        for entry in std::fs::read_dir(&dir).into_iter().flatten().flatten() {
            let path = entry.path();
            if path.is_dir() {
                stack.push(path);
            } else if path.extension().is_some_and(|e| e == "md") {
                docs.push(
                    path.strip_prefix(root())
                        .expect("below the root")
                        .to_path_buf(),
                );
            }
        }
    }
    for entry in std::fs::read_dir(root().join("models"))
        .expect("models")
        .flatten()
    {
        let card = entry.path().join("README.md");
        if card.is_file() {
            docs.push(
                card.strip_prefix(root())
                    .expect("below the root")
                    .to_path_buf(),
            );
        }
    }
    docs.retain(|d| root().join(d).is_file());
    docs.sort();
    docs
}

/// The text outside fenced code blocks, line by line (numbered from 1).
fn prose(text: &str) -> Vec<(usize, &str)> {
    let mut fenced = false;
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        if line.trim_start().starts_with("```") {
            fenced = !fenced;
            continue;
        }
        if !fenced {
            out.push((i + 1, line));
        }
    }
    out
}

/// GitHub's anchor for a heading: lowercased, punctuation other than `-` and `_` dropped,
/// spaces made hyphens; repeats get `-1`, `-2`, ….
fn anchors(text: &str) -> Vec<String> {
    let mut seen: HashMap<String, usize> = HashMap::new();
    let mut out = Vec::new();
    for (_, line) in prose(text) {
        let Some(heading) = line.strip_prefix('#') else {
            continue;
        };
        let heading = heading.trim_start_matches('#');
        if !heading.starts_with(' ') {
            continue;
        }
        let slug: String = heading
            .trim()
            .to_lowercase()
            .chars()
            .filter(|c| c.is_alphanumeric() || *c == ' ' || *c == '-' || *c == '_')
            .map(|c| if c == ' ' { '-' } else { c })
            .collect();
        let n = seen.entry(slug.clone()).or_insert(0);
        out.push(if *n == 0 {
            slug.clone()
        } else {
            format!("{slug}-{n}")
        });
        *n += 1;
    }
    out
}

/// The targets of the inline links `[text](target)` on a line.
fn link_targets(line: &str) -> Vec<&str> {
    let mut out = Vec::new();
    let mut rest = line;
    while let Some(i) = rest.find("](") {
        let after = &rest[i + 2..];
        let Some(end) = after.find(')') else { break };
        let target = after[..end].split_whitespace().next().unwrap_or("");
        out.push(target);
        rest = &after[end..];
    }
    out
}

/// What is written between backticks on a line.
fn code_spans(line: &str) -> Vec<&str> {
    line.split('`').skip(1).step_by(2).collect()
}

/// Repository folders whose paths are checked when written in backticks.
const TRACKED: [&str; 12] = [
    "src/",
    "tests/",
    "models/",
    "docs/",
    "tools/",
    "scripts/",
    "migrations/",
    "web/",
    "clients/",
    "openapi/",
    ".ci/",
    "docker/",
];

#[test]
fn every_link_anchor_and_path_in_the_docs_resolves() {
    let docs = documents();
    assert!(
        docs.len() >= 8,
        "README, CONTRIBUTING, docs/ and the cards: {docs:?}"
    );
    let mut broken = Vec::new();
    for doc in &docs {
        let text = std::fs::read_to_string(root().join(doc)).expect("read doc");
        let dir = root().join(doc).parent().expect("dir").to_path_buf();
        let own = anchors(&text);
        for (n, line) in prose(&text) {
            for target in link_targets(line) {
                if target.is_empty() || target.contains("://") || target.starts_with("mailto:") {
                    continue;
                }
                let (path, anchor) = match target.split_once('#') {
                    Some((p, a)) => (p, Some(a)),
                    None => (target, None),
                };
                let file = if path.is_empty() {
                    root().join(doc)
                } else {
                    dir.join(path)
                };
                if !file.exists() {
                    broken.push(format!("{}:{n}: no file {target}", doc.display()));
                    continue;
                }
                if let Some(anchor) = anchor {
                    let known = if path.is_empty() {
                        own.clone()
                    } else {
                        anchors(&std::fs::read_to_string(&file).unwrap_or_default())
                    };
                    if !known.iter().any(|a| a == anchor) {
                        broken.push(format!(
                            "{}:{n}: no heading for #{anchor} in {target}",
                            doc.display()
                        ));
                    }
                }
            }
            for span in code_spans(line) {
                let path = span.trim();
                if !TRACKED.iter().any(|t| path.starts_with(t))
                    || path.contains(|c: char| c.is_whitespace() || "<>*{}$|…".contains(c))
                {
                    continue;
                }
                // `src/x.rs:120` and `docs/a.md#b` name the file.
                let path = path.split([':', '#']).next().unwrap_or(path);
                if !root().join(path).exists() {
                    broken.push(format!("{}:{n}: no path {path}", doc.display()));
                }
            }
        }
    }
    assert!(
        broken.is_empty(),
        "{} broken:\n{}",
        broken.len(),
        broken.join("\n")
    );
}

#[test]
fn the_docs_speak_of_the_project_as_it_is() {
    let issue = |line: &str| {
        let lower = line.to_lowercase();
        lower.match_indices("issue ").any(|(i, _)| {
            lower[i + 6..]
                .chars()
                .next()
                .is_some_and(|c| c.is_ascii_digit())
        })
    };
    let mut found = Vec::new();
    for doc in documents() {
        let text = std::fs::read_to_string(root().join(&doc)).expect("read doc");
        for (n, line) in text.lines().enumerate() {
            let lower = line.to_lowercase();
            if lower
                .split(|c: char| !c.is_alphanumeric())
                .any(|w| w == "session")
                || issue(line)
            {
                found.push(format!("{}:{}: {line}", doc.display(), n + 1));
            }
        }
        let lines = text.lines().count();
        let limit = if doc == Path::new("README.md") {
            Some(300)
        } else if doc.starts_with("models") {
            Some(250)
        } else {
            None
        };
        if let Some(limit) = limit {
            assert!(
                lines <= limit,
                "{} has {lines} lines, at most {limit}",
                doc.display()
            );
        }
    }
    assert!(found.is_empty(), "work-log words:\n{}", found.join("\n"));
}

#[test]
fn anchors_are_githubs() {
    assert_eq!(
        anchors("# Two commands\n## Limits: what a client gets at each\n```\n# not\n```\n## Two commands"),
        ["two-commands", "limits-what-a-client-gets-at-each", "two-commands-1"]
    );
    assert_eq!(
        link_targets("see [a](docs/api.md#keys) and [b](#x)"),
        ["docs/api.md#keys", "#x"]
    );
}

/// Every model card's evaluation table is made from its committed `eval.json`, as
/// `choreo eval --card-table models/<id>/eval.json` writes it.
#[test]
fn model_cards_show_their_committed_evaluation() {
    let mut checked = 0;
    for entry in std::fs::read_dir(root().join("models"))
        .expect("models")
        .flatten()
    {
        let dir = entry.path();
        let (card, eval) = (dir.join("README.md"), dir.join("eval.json"));
        if !card.is_file() || !eval.is_file() {
            continue;
        }
        let result: choreo::eval::EvalResult =
            serde_json::from_str(&std::fs::read_to_string(&eval).expect("eval.json"))
                .unwrap_or_else(|e| panic!("{}: {e}", eval.display()));
        let table = choreo::eval::tables::card_table(&result);
        let text = std::fs::read_to_string(&card).expect("card");
        assert!(
            text.contains(&table),
            "{} does not show its eval.json's table; paste the output of \
             `choreo eval --card-table {}`:\n{table}",
            card.display(),
            eval.display()
        );
        checked += 1;
    }
    assert!(checked >= 5, "{checked} cards with an evaluation");
}
