//! The client SDKs agree with the wire contract: the ctypes structures of
//! `clients/python/formation_client/wire.py` and the structs of `clients/c/formation_wire.h` have
//! the size, alignment, field offsets and sizes (and the Python ones the iceoryx2 type names) that
//! `formation schema --json` prints for the current code.

use formation_tests::{bin, temp_dir, workspace_root};
use serde_json::Value;
use std::fmt::Write as _;
use std::process::Command;

fn schema_json() -> (String, Value) {
    let o = Command::new(bin("formation"))
        .args(["schema", "--json"])
        .output()
        .expect("formation schema starts");
    assert!(o.status.success(), "formation schema --json failed");
    let text = String::from_utf8(o.stdout).expect("UTF-8");
    let v = serde_json::from_str(&text).expect("JSON");
    (text, v)
}

#[test]
fn the_python_ctypes_structures_match_the_schema_field_by_field() {
    // The check needs only the standard library: the venv's Python if there is one, else python3.
    let py = formation_tests::python_with_iceoryx2()
        .map(|p| p.into_os_string())
        .unwrap_or_else(|_| "python3".into());
    let dir = temp_dir("clients-python");
    let (text, _) = schema_json();
    let path = dir.join("schema.json");
    std::fs::write(&path, text).unwrap();
    let o = match Command::new(&py)
        .arg(workspace_root().join("clients/python/check_layout.py"))
        .arg(&path)
        .output()
    {
        Ok(o) => o,
        Err(e) if std::env::var("FORMATION_REQUIRE_PYTHON").as_deref() != Ok("1") => {
            eprintln!("skipped: cannot start {py:?}: {e}");
            return;
        }
        Err(e) => panic!("cannot start {py:?}: {e}"),
    };
    assert!(
        o.status.success(),
        "clients/python/formation_client/wire.py differs from `formation schema --json` \
         (regenerate: formation schema --json | python3 clients/generate.py):\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(String::from_utf8_lossy(&o.stdout).contains("17 types"));
    let _ = std::fs::remove_dir_all(&dir);
}

/// A C translation unit that includes the header and asserts, at compile time, every size,
/// alignment, offset and field size of the schema.
fn c_checks(schema: &Value) -> String {
    let mut c = String::from(
        "#include <stddef.h>\n#include \"formation_wire.h\"\n#define FM_SIZE(T, f) sizeof(((T *)0)->f)\n",
    );
    for t in schema["types"].as_array().expect("types") {
        let name = format!("fm_{}", t["name"].as_str().unwrap());
        writeln!(
            c,
            "_Static_assert(sizeof({name}) == {}, \"size of {name}\");",
            t["size"]
        )
        .unwrap();
        writeln!(
            c,
            "_Static_assert(_Alignof({name}) == {}, \"align of {name}\");",
            t["align"]
        )
        .unwrap();
        for f in t["fields"].as_array().expect("fields") {
            let field = f["name"].as_str().unwrap();
            writeln!(
                c,
                "_Static_assert(offsetof({name}, {field}) == {}, \"{name}.{field} offset\");",
                f["offset"]
            )
            .unwrap();
            writeln!(
                c,
                "_Static_assert(FM_SIZE({name}, {field}) == {}, \"{name}.{field} size\");",
                f["size"]
            )
            .unwrap();
        }
        if let Some(iox) = t["iceoryx2"].as_str() {
            let upper = t["name"].as_str().unwrap().to_uppercase();
            writeln!(
                c,
                "_Static_assert(sizeof(FM_{upper}_TYPE_NAME) == {}, \"{upper} type name\");",
                iox.len() + 1
            )
            .unwrap();
        }
    }
    c
}

#[test]
fn the_c_header_matches_the_schema_field_by_field() {
    let (_, schema) = schema_json();
    let dir = temp_dir("clients-c");
    let src = dir.join("check.c");
    std::fs::write(&src, c_checks(&schema)).unwrap();
    let cc = std::env::var_os("CC").unwrap_or_else(|| "cc".into());
    let o = Command::new(&cc)
        .args(["-std=c11", "-Wall", "-Werror", "-fsyntax-only", "-I"])
        .arg(workspace_root().join("clients/c"))
        .arg(&src)
        .output()
        .unwrap_or_else(|e| panic!("cannot start the C compiler {cc:?} (the Rust linker): {e}"));
    assert!(
        o.status.success(),
        "clients/c/formation_wire.h differs from `formation schema --json` \
         (regenerate: formation schema --json | python3 clients/generate.py):\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    // The header also compiles as C++.
    let cxx = dir.join("check.cpp");
    std::fs::write(&cxx, "#include \"formation_wire.h\"\nint main() { fm_AgentTelemetry t{}; return (int)t.step; }\n").unwrap();
    if let Ok(o) = Command::new("c++")
        .args(["-std=c++17", "-fsyntax-only", "-I"])
        .arg(workspace_root().join("clients/c"))
        .arg(&cxx)
        .output()
    {
        assert!(
            o.status.success(),
            "as C++: {}",
            String::from_utf8_lossy(&o.stderr)
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}
