//! Rust types for the ROS 1 messages in `msg/` (roslibrust's code generator; no ROS install
//! needed). Each type carries its ROS md5 sum, which a ROS master checks on every connection.

fn main() {
    // Read when the script runs, not when it is compiled: a target folder shared by clones at
    // other paths (CI's, outside the clone) reuses the compiled script.
    let root =
        std::path::PathBuf::from(std::env::var("CARGO_MANIFEST_DIR").expect("CARGO_MANIFEST_DIR"))
            .join("msg");
    let (tokens, inputs) =
        roslibrust_codegen::find_and_generate_ros_messages_without_ros_package_path(vec![
            root.clone(),
        ])
        .unwrap_or_else(|e| panic!("ROS message definitions in {}: {e}", root.display()));
    let out =
        std::path::PathBuf::from(std::env::var("OUT_DIR").expect("OUT_DIR")).join("ros_msgs.rs");
    std::fs::write(&out, tokens.to_string())
        .unwrap_or_else(|e| panic!("writing {}: {e}", out.display()));
    for path in inputs {
        println!("cargo:rerun-if-changed={}", path.display());
    }
    println!("cargo:rerun-if-changed=msg");
}
