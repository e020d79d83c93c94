//! esgm from C and C++, as programs written in those languages meet it (SPEC L3): the
//! C ABI's test program (`tests/c/api_test.c`), plain and under AddressSanitizer and
//! UndefinedBehaviorSanitizer; the C++ wrapper's (`esgm-shm/cpp/tests/api_test.cpp`),
//! built with g++ and with clang++, warnings as errors; and the examples
//! (`esgm-shm/cpp/examples`). Each is built with CMake against the esgm package of this
//! checkout, linked to the `libesgm_c.so` this test run built, and run on both runtimes:
//! in process, and against a coordinator on a thread of this test.
//!
//! CMake, g++ and clang++ are needed (`.ci/run` installs them): in CI a missing one
//! fails these tests; elsewhere they are skipped with a note.
#![allow(clippy::panic, clippy::unwrap_used, clippy::expect_used)] // a test fails loudly

#[path = "../../apps/cli/tests/common/capability.rs"]
mod capability;

use std::io::{BufRead as _, BufReader, Write as _};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::{Mutex, OnceLock};
use std::time::{Duration, Instant};

use esgm_shm::control::{Coordinator, CoordinatorThread, Registry};

/// How long one program may run before it counts as hung.
const RUN_TIMEOUT: Duration = Duration::from_secs(300);

fn checkout() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..").canonicalize().unwrap()
}

/// The directory of the `libesgm_c.so` this test run built: this test's own
/// directory (`deps`), where cargo writes the library's every crate type in the one
/// compilation that made the rlib this test links (the profile directory's copy is
/// refreshed only by `cargo build`, so it may be older).
fn library_dir() -> PathBuf {
    let exe = std::env::current_exe().unwrap();
    let deps = exe.parent().unwrap().to_path_buf();
    assert!(deps.join("libesgm_c.so").is_file(), "no libesgm_c.so in {}", deps.display());
    deps
}

/// Where the CMake builds go.
fn build_root() -> PathBuf {
    PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("esgm-c-programs")
}

/// What these tests need of the machine, or why not.
fn tools() -> Result<(), String> {
    for (tool, args) in
        [("cmake", ["--version"]), ("g++", ["--version"]), ("clang++", ["--version"])]
    {
        capability::runs(tool, &args)?;
    }
    Ok(())
}

/// Configures and builds the CMake project `source` into `build` (once per process),
/// with `options`; returns the build directory.
fn cmake(source: &str, build: &str, options: &[&str], cxx: Option<&str>) -> PathBuf {
    static BUILT: OnceLock<Mutex<()>> = OnceLock::new();
    let _one_at_a_time = BUILT.get_or_init(|| Mutex::new(())).lock().unwrap();
    let dir = build_root().join(build);
    let library = format!("-DESGM_LIBRARY_DIR={}", library_dir().display());
    let mut configure = Command::new("cmake");
    configure
        .arg("-S")
        .arg(checkout().join(source))
        .arg("-B")
        .arg(&dir)
        .arg(&library)
        .arg("-DCMAKE_BUILD_TYPE=Debug")
        .args(options);
    if let Some(cxx) = cxx {
        configure.env("CXX", cxx);
    }
    run_ok(&mut configure, "cmake configure");
    run_ok(Command::new("cmake").arg("--build").arg(&dir).arg("-j2"), "cmake --build");
    dir
}

/// Runs a build step; its output is shown when it fails.
fn run_ok(command: &mut Command, what: &str) {
    let out = command.output().unwrap_or_else(|e| panic!("{what}: cannot run: {e}"));
    assert!(
        out.status.success(),
        "{what} failed ({}):\n{}\n{}",
        out.status,
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Waits for `child` with a deadline; kills it and fails if it runs longer.
fn finish(mut child: Child, what: &str) -> String {
    let deadline = Instant::now() + RUN_TIMEOUT;
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            let out = child.wait_with_output().unwrap();
            let text = format!(
                "{}{}",
                String::from_utf8_lossy(&out.stdout),
                String::from_utf8_lossy(&out.stderr)
            );
            assert!(status.success(), "{what} failed ({status}):\n{text}");
            return text;
        }
        if Instant::now() > deadline {
            let _killed = child.kill();
            let out = child.wait_with_output().unwrap();
            panic!(
                "{what} did not finish within {RUN_TIMEOUT:?}:\n{}{}",
                String::from_utf8_lossy(&out.stdout),
                String::from_utf8_lossy(&out.stderr)
            );
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Runs `program args…` to completion (status 0), under the sanitizers' strict options.
fn run(program: &Path, args: &[&str]) -> String {
    run_with(program, args, &library_dir())
}

/// [`run`], loading libesgm_c from `library`.
fn run_with(program: &Path, args: &[&str], library: &Path) -> String {
    let what = format!("{} {}", program.display(), args.join(" "));
    let child = program_command(program)
        .env("LD_LIBRARY_PATH", library)
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| panic!("cannot run {what}: {e}"));
    finish(child, &what)
}

fn program_command(program: &Path) -> Command {
    let mut c = Command::new(program);
    // cargo runs tests with LD_LIBRARY_PATH naming the profile directory, whose
    // libesgm_c.so may be an older build, and it would win over the program's RUNPATH.
    c.env("LD_LIBRARY_PATH", library_dir());
    // A sanitizer's report fails the program (and so the test); leaks are reported.
    c.env("ASAN_OPTIONS", "abort_on_error=0:detect_leaks=1:halt_on_error=1")
        .env("UBSAN_OPTIONS", "print_stacktrace=1:halt_on_error=1")
        .stdin(Stdio::null());
    c
}

/// A coordinator on a thread of this test, in a domain of its own.
fn coordinator(prefix: &str) -> CoordinatorThread {
    let domain = esgm_shm::unique_domain(prefix);
    Coordinator::spawn(&domain, Registry::new(esgm_core::TypeRegistry::with_library()))
        .expect("start a coordinator")
}

/// The C ABI's tests on both runtimes, in a program built `build` with `options`.
fn c_api(build: &str, options: &[&str]) {
    let dir = cmake("esgm-shm/c/tests/c", build, options, None);
    let program = dir.join("api_test");
    let out = run(&program, &["in-process"]);
    assert!(out.contains("every check held"), "{out}");
    let c = coordinator("c-api");
    let domain = c.domain().to_owned();
    let shm = run(&program, &["shm", &domain]);
    let killed = run(&program, &["killed-writer", &domain]);
    // The domain ends as `esgm down` ends it: the killed writer stays counted as a
    // user of its futex words, and its kept history outlives it by design.
    drop(c);
    esgm_shm::process::remove_domain_files(&domain);
    assert!(shm.contains("every check held"), "{shm}");
    assert!(killed.contains("every check held"), "{killed}");
}

#[test]
fn the_c_abi_on_both_runtimes() {
    if capability::needs("cmake, g++ and clang++", tools()).is_none() {
        return;
    }
    c_api("c", &[]);
}

#[test]
fn the_c_abi_under_address_and_undefined_behavior_sanitizers() {
    if capability::needs("cmake, g++ and clang++", tools()).is_none() {
        return;
    }
    c_api("c-sanitized", &["-DESGM_SANITIZE=ON"]);
}

/// Handles used after the domain went down: the program connects and says so, the
/// coordinator stops, and every call it then makes returns a status (no crash, no
/// sanitizer report).
#[test]
fn handles_after_the_domain_went_down() {
    if capability::needs("cmake, g++ and clang++", tools()).is_none() {
        return;
    }
    let dir = cmake("esgm-shm/c/tests/c", "c-sanitized", &["-DESGM_SANITIZE=ON"], None);
    let c = coordinator("c-down");
    let domain = c.domain().to_owned();
    let mut child = program_command(&dir.join("api_test"))
        .args(["down", &domain])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut stdout = BufReader::new(child.stdout.take().unwrap());
    let mut line = String::new();
    stdout.read_line(&mut line).unwrap();
    assert_eq!(line.trim(), "connected", "the program did not connect");
    drop(c); // the domain goes down
    writeln!(child.stdin.take().unwrap(), "go").unwrap();
    let errors = finish(child, "api_test down");
    let mut rest = String::new();
    std::io::Read::read_to_string(&mut stdout, &mut rest).unwrap();
    assert!(rest.contains("every check held"), "{rest}{errors}");
}

#[test]
fn the_cpp_wrapper_with_gcc_and_clang_on_both_runtimes() {
    if capability::needs("cmake, g++ and clang++", tools()).is_none() {
        return;
    }
    for (build, cxx) in [("cpp-gcc", "g++"), ("cpp-clang", "clang++")] {
        let dir = cmake("esgm-shm/cpp/tests", build, &[], Some(cxx));
        let program = dir.join("cpp_api_test");
        let out = run(&program, &["in-process"]);
        assert!(out.contains("every check held"), "{cxx}: {out}");
        let c = coordinator("cpp-api");
        let out = run(&program, &["shm", c.domain()]);
        assert!(out.contains("every check held"), "{cxx}: {out}");
    }
}

/// The C++ camera renders the Rust camera's scene, pixel for pixel, with the same
/// ground truth: `esgm demo --config tutorial_cpp.toml` checks it against the same.
#[test]
fn the_cpp_camera_renders_the_rust_scene() {
    if capability::needs("cmake, g++ and clang++", tools()).is_none() {
        return;
    }
    let dir = cmake("esgm-shm/cpp/tests", "cpp-gcc", &[], Some("g++"));
    for (seed, blobs, t) in
        [(0_u64, 3_usize, 1_795_000_000_123_456_789_i64), (7, 5, 42), (3, 1, -5)]
    {
        let out = run(
            &dir.join("cpp_api_test"),
            &["scene", &seed.to_string(), &blobs.to_string(), &t.to_string()],
        );
        let scene =
            camera_publisher::SyntheticScene::builder().blobs(blobs).seed(seed).create().unwrap();
        let frame = camera_publisher::FrameSource::frame(&scene, t);
        let mut hash: u64 = 1_469_598_103_934_665_603;
        for b in frame.image_data.iter() {
            hash = (hash ^ u64::from(*b)).wrapping_mul(1_099_511_628_211);
        }
        let truth: Vec<String> =
            scene.truth(t).iter().map(|b| format!("{} {} {}", b.x, b.y, b.size)).collect();
        let expected = format!("{hash}\n{}\n", truth.join("\n"));
        assert_eq!(out, expected, "seed {seed}, {blobs} blobs, t {t}");
    }
}

/// The examples build with warnings as errors, and the seed's tutorial in C++ and the
/// C robot run in process.
#[test]
fn the_examples_build_and_run() {
    if capability::needs("cmake, g++ and clang++", tools()).is_none() {
        return;
    }
    let dir = cmake("esgm-shm/cpp/examples", "examples", &["-DESGM_WERROR=ON"], None);
    for program in ["tutorial_camera", "driving_direction_unit", "tutorial", "robot_c"] {
        assert!(dir.join(program).is_file(), "{program} was not built");
    }
    let out = run(&dir.join("tutorial"), &[]);
    assert!(out.contains("get current driving direction... valid at"), "{out}");
    assert!(out.contains("got sample driving_dir ="), "{out}");
    let out = run(&dir.join("robot_c"), &[]);
    assert!(out.contains("20 states pushed"), "{out}");
    // Against a system of processes too.
    let c = coordinator("c-robot");
    let out = run(&dir.join("robot_c"), &[c.domain(), "5"]);
    assert!(out.contains("5 states pushed"), "{out}");
}

/// Installed like a C++ library: `cmake --install` of `esgm-shm/cpp` into a prefix, the
/// examples built against that package (found through CMAKE_PREFIX_PATH, not the
/// checkout), and a C program built with `pkg-config esgm`, shared and static.
#[test]
fn the_installed_package_builds_programs() {
    if capability::needs(
        "cmake, g++, clang++ and pkg-config",
        tools().and_then(|()| capability::runs("pkg-config", &["--version"])),
    )
    .is_none()
    {
        return;
    }
    let prefix = build_root().join("prefix");
    let _fresh = std::fs::remove_dir_all(&prefix);
    let install = cmake(
        "esgm-shm/cpp",
        "install",
        &[&format!("-DCMAKE_INSTALL_PREFIX={}", prefix.display())],
        None,
    );
    run_ok(Command::new("cmake").arg("--install").arg(&install), "cmake --install");
    for file in [
        "lib/libesgm_c.so",
        "lib/libesgm_c.a",
        "include/esgm.h",
        "include/esgm/esgm.hpp",
        "lib/cmake/esgm/esgmConfig.cmake",
        "lib/cmake/esgm/esgmConfigVersion.cmake",
        "lib/pkgconfig/esgm.pc",
    ] {
        assert!(prefix.join(file).is_file(), "{file} was not installed");
    }

    let dir = build_root().join("examples-installed");
    let _fresh = std::fs::remove_dir_all(&dir);
    run_ok(
        Command::new("cmake")
            .arg("-S")
            .arg(checkout().join("esgm-shm/cpp/examples"))
            .arg("-B")
            .arg(&dir)
            .arg(format!("-DCMAKE_PREFIX_PATH={}", prefix.display()))
            .arg("-DESGM_WERROR=ON"),
        "cmake configure against the installed package",
    );
    let cache = std::fs::read_to_string(dir.join("CMakeCache.txt")).unwrap();
    let found = prefix.join("lib/cmake/esgm");
    assert!(
        cache.contains(&format!("esgm_DIR:PATH={}", found.display())),
        "the examples did not find the installed package"
    );
    run_ok(Command::new("cmake").arg("--build").arg(&dir).arg("-j2"), "cmake --build");
    let installed = prefix.join("lib");
    let out = run_with(&dir.join("robot_c"), &["", "3"], &installed);
    assert!(out.contains("3 states pushed"), "{out}");

    // pkg-config: the shared library, then the static one with its private libraries.
    let pc = prefix.join("lib/pkgconfig");
    let flags = |args: &[&str]| {
        let out = Command::new("pkg-config")
            .args(args)
            .arg("esgm")
            .env("PKG_CONFIG_PATH", &pc)
            .output()
            .unwrap();
        assert!(out.status.success(), "pkg-config {args:?} esgm failed");
        String::from_utf8(out.stdout)
            .unwrap()
            .split_whitespace()
            .map(str::to_owned)
            .collect::<Vec<_>>()
    };
    let source = checkout().join("esgm-shm/cpp/examples/robot_c.c");
    let shared = dir.join("robot_c_pkg_config");
    run_ok(
        Command::new("cc")
            .args(["-Wall", "-Wextra", "-Werror"])
            .arg(&source)
            .args(flags(&["--cflags", "--libs"]))
            .arg(format!("-Wl,-rpath,{}", prefix.join("lib").display()))
            .arg("-o")
            .arg(&shared),
        "cc with pkg-config",
    );
    let out = run_with(&shared, &["", "2"], &installed);
    assert!(out.contains("2 states pushed"), "{out}");
    let statically = dir.join("robot_c_static");
    run_ok(
        Command::new("cc")
            .arg(&source)
            .args(flags(&["--cflags"]))
            .arg(prefix.join("lib/libesgm_c.a"))
            .args(flags(&["--libs-only-other", "--static"]))
            .args(flags(&["--libs", "--static"]).into_iter().filter(|f| f != "-lesgm_c"))
            .arg("-o")
            .arg(&statically),
        "cc with the static library",
    );
    let out = run(&statically, &["", "2"]);
    assert!(out.contains("2 states pushed"), "{out}");
}
