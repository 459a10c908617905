//! The user references of the two TOML formats stay true: every example in `docs/scene-format.md` loads with
//! the scene it names through the scene loader, every example in `docs/relight-scripts.md` parses and resolves
//! against the light groups it names through the script parser, and every field either parser accepts (as its
//! unknown-field error lists them) is shown in an example and named in the text.

use std::path::{Path, PathBuf};

use firmware_sim::script::{ScriptFile, TableGroups};
use radiosity_host::scene::Scene;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn doc(name: &str) -> String {
    std::fs::read_to_string(root().join("docs").join(name)).unwrap_or_else(|e| panic!("docs/{name}: {e}"))
}

/// The ```toml blocks of a markdown text, in order.
fn toml_blocks(markdown: &str) -> Vec<String> {
    let mut blocks = Vec::new();
    let mut current: Option<String> = None;
    for line in markdown.lines() {
        match (&mut current, line.trim_end()) {
            (None, "```toml") => current = Some(String::new()),
            (Some(block), "```") => {
                blocks.push(std::mem::take(block));
                current = None;
            }
            (Some(block), _) => {
                block.push_str(line);
                block.push('\n');
            }
            (None, _) => {}
        }
    }
    assert!(current.is_none(), "unterminated ```toml block");
    blocks
}

/// What the first line of `block` says after `prefix` (each example names what it belongs to).
fn header<'a>(block: &'a str, prefix: &str) -> &'a str {
    let first = block.lines().next().unwrap_or_default();
    first.strip_prefix(prefix).unwrap_or_else(|| panic!("example does not start with {prefix:?}:\n{block}"))
}

/// The keys and table names used in `block`: every name before a `=` and every part of a `[table]` or
/// `[[array.of.tables]]` header, outside strings and comments.
fn keys(block: &str) -> Vec<String> {
    let mut out = Vec::new();
    for line in block.lines() {
        // Strings out first (a `#` or `=` inside one is text), then the comment.
        let mut code = String::new();
        let mut in_string = false;
        for c in line.chars() {
            if c == '"' {
                in_string = !in_string;
            } else if !in_string {
                code.push(c);
            }
        }
        let code = code.split('#').next().unwrap_or_default().trim();
        if code.starts_with('[') && !code.contains('=') {
            out.extend(code.trim_matches(['[', ']']).split('.').map(|k| k.trim().to_owned()));
            continue;
        }
        for (i, _) in code.match_indices('=') {
            let before = code[..i].trim_end();
            let start = before
                .rfind(|c: char| !(c.is_ascii_alphanumeric() || c == '_' || c == '-'))
                .map_or(0, |k| k + 1);
            if start < before.len() {
                out.push(before[start..].to_owned());
            }
        }
    }
    out
}

/// The field names an unknown-field error lists after "expected" (serde: "expected one of `a`, `b`" or
/// "expected `a`").
fn expected_fields(error: &str) -> Vec<String> {
    let (_, list) = error.split_once("expected").unwrap_or_else(|| panic!("no field list in: {error}"));
    let list = list.lines().next().unwrap_or_default();
    list.split('`').skip(1).step_by(2).map(str::to_owned).collect()
}

/// Checks that every field in `fields` is a key of some example in `blocks` and is named in `markdown` (in
/// backticks, or as a table header: `[meshing]`, `[[script.frame]]`).
fn assert_documented(fields: &[String], blocks: &[String], markdown: &str, doc_name: &str) {
    let shown: Vec<String> = blocks.iter().flat_map(|b| keys(b)).collect();
    for field in fields {
        assert!(shown.contains(field), "docs/{doc_name}: no example sets `{field}`");
        let named = [format!("`{field}`"), format!("[{field}]"), format!(".{field}]")];
        assert!(
            named.iter().any(|n| markdown.contains(n.as_str())),
            "docs/{doc_name}: the text never names `{field}`"
        );
    }
}

/// A TOML file in a fresh temporary folder.
fn temp_toml(tag: &str, k: usize, text: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("radiosity-format-docs-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(format!("example-{k}.toml"));
    std::fs::write(&path, text).unwrap();
    path
}

/// The scene loader's error for `toml` (any scene will do: the TOML file is parsed before it is checked
/// against the materials).
fn scene_error(toml: &str) -> String {
    let path = temp_toml("error", 0, toml);
    match Scene::load_with_toml(&root().join("scenes/cornell-box.obj"), Some(&path)) {
        Ok(_) => panic!("the scene loader accepted {toml:?}"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn every_scene_settings_example_loads_and_every_field_is_documented() {
    let markdown = doc("scene-format.md");
    let blocks = toml_blocks(&markdown);
    assert!(blocks.len() >= 3, "docs/scene-format.md has {} examples", blocks.len());
    for (k, block) in blocks.iter().enumerate() {
        let obj = header(block, "# for ").split_whitespace().next().unwrap_or_default();
        let path = temp_toml("scene", k, block);
        if let Err(e) = Scene::load_with_toml(&root().join(obj), Some(&path)) {
            panic!("docs/scene-format.md example {k} (with {obj}) does not load: {e}\n{block}");
        }
    }
    // Top level, `[meshing]` and `[[light_group]]`: the fields the loader accepts, from its own errors.
    let mut fields = Vec::new();
    for toml in
        ["unknown_field = 1\n", "[meshing]\nunknown_field = 1\n", "[[light_group]]\nunknown_field = 1\n"]
    {
        fields.extend(expected_fields(&scene_error(toml)));
    }
    for known in ["meshing", "light_group", "max_patch_edge", "repair", "name", "intensity"] {
        assert!(fields.iter().any(|f| f == known), "the field lists {fields:?} lack {known}");
    }
    assert_documented(&fields, &blocks, &markdown, "scene-format.md");
}

#[test]
fn every_relight_script_example_parses_and_resolves_and_every_field_is_documented() {
    let markdown = doc("relight-scripts.md");
    let blocks = toml_blocks(&markdown);
    assert!(blocks.len() >= 3, "docs/relight-scripts.md has {} examples", blocks.len());
    let mut resolved: Vec<firmware_sim::script::OwnedScript> = Vec::new();
    for (k, block) in blocks.iter().enumerate() {
        let names: Vec<&str> =
            header(block, "# for light groups (table order): ").split(',').map(str::trim).collect();
        let ids = names.iter().map(|n| radiosity_core::group_id(n)).collect();
        let groups = TableGroups::from_ids(ids).named(names.iter().copied());
        let origin = format!("docs/relight-scripts.md example {k}");
        let file = ScriptFile::parse(block, &origin)
            .and_then(|f| f.resolve(&groups))
            .unwrap_or_else(|e| panic!("{e}\n{block}"));
        for s in file.scripts {
            // Examples that show one script in two forms (same name) must mean the same frames.
            if let Some(same) = resolved.iter().find(|r| r.name == s.name) {
                assert_eq!((&same.initial, &same.frames), (&s.initial, &s.frames), "{origin}: {}", s.name);
            }
            resolved.push(s);
        }
    }
    assert!(
        resolved.windows(2).any(|w| w[0].name == w[1].name),
        "the named and positional forms of one script are compared"
    );
    let parse_error = |toml: &str| ScriptFile::parse(toml, "t.toml").map(|_| ()).unwrap_err().to_string();
    let mut fields = Vec::new();
    for toml in [
        "unknown_field = 1\n",
        "[[script]]\nunknown_field = 1\n",
        "[[script]]\n[[script.frame]]\nunknown_field = 1\n",
    ] {
        fields.extend(expected_fields(&parse_error(toml)));
    }
    for known in ["script", "frame", "initial", "boot_budget", "ramp", "repeat"] {
        assert!(fields.iter().any(|f| f == known), "the field lists {fields:?} lack {known}");
    }
    assert_documented(&fields, &blocks, &markdown, "relight-scripts.md");
}

#[test]
fn key_scan_sees_keys_headers_and_inline_tables_but_not_text() {
    let block =
        "[[script.frame]]\nintensity = { light = [1.0, 1.0, 1.0] }  # ramp = true\ndescription = \"a = b\"\n";
    assert_eq!(keys(block), ["script", "frame", "intensity", "light", "description"]);
    assert_eq!(
        expected_fields("unknown field `x`, expected one of `a`, `b_c`\n"),
        ["a".to_owned(), "b_c".to_owned()]
    );
}
