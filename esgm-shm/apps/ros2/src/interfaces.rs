//! `esgm ros2 msg TYPE` and `esgm ros2 pkg DIR`: the ROS 2 interfaces esgm's types are
//! exported as, for a ROS 2 workspace to build.
//!
//! Types are looked up where they are without a running system first: esgm's library,
//! then a system file's `[[type]]`s (`--config`, read by esgm's own loader); only a type
//! found in neither is asked of the domain. So `ros2 interface show`'s habit holds: a
//! library type's definition needs nothing running.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::{Context as _, bail};
use esgm_core::{EntityStructureType, Esgm as _, TypeRegistry};
use esgm_ros2msg::generated::{PACKAGE, Schema};
use esgm_ros2msg::mapping::RosType;
use esgm_shm::ShmEsgm;

/// Where types come from: the library, a system file, and (only if asked for a type
/// in neither) the domain, connected once.
pub struct Types {
    library: TypeRegistry,
    file: BTreeMap<String, EntityStructureType>,
    domain: String,
    connected: Option<Result<ShmEsgm, String>>,
}

impl Types {
    /// The library's types, `config`'s, and `domain`'s if needed.
    pub fn new(domain: &str, config: Option<&Path>) -> anyhow::Result<Self> {
        let mut file = BTreeMap::new();
        if let Some(path) = config {
            let text = std::fs::read_to_string(path)
                .with_context(|| format!("cannot read {}", path.display()))?;
            let base = path.parent().unwrap_or(Path::new("."));
            // Only its types are used: its programs are not looked for.
            let plan = esgm_cli::config::parse(&path.display().to_string(), &text, base)?;
            for item in plan.types {
                let (name, ty) = item.what;
                file.insert(name, ty);
            }
        }
        Ok(Self {
            library: TypeRegistry::with_library(),
            file,
            domain: domain.to_owned(),
            connected: None,
        })
    }

    /// The types the system file declares, in its order of names.
    pub fn declared(&self) -> Vec<String> {
        self.file.keys().cloned().collect()
    }

    /// Every type the domain has registered.
    pub fn of_domain(&mut self) -> anyhow::Result<Vec<String>> {
        let esgm = self.domain()?;
        Ok(esgm.entity_structure_type_names()?)
    }

    fn domain(&mut self) -> anyhow::Result<&ShmEsgm> {
        let domain = self.domain.clone();
        let connected = self.connected.get_or_insert_with(|| {
            ShmEsgm::builder()
                .domain(&domain)
                .tool()
                .connect()
                .map_err(|e| format!("cannot reach the esgm system `{domain}`: {e}"))
        });
        connected.as_ref().map_err(|e| anyhow::anyhow!("{e}"))
    }

    /// The definition of `name`: the system file's over the library's, then the
    /// domain's.
    pub fn get(&mut self, name: &str) -> anyhow::Result<EntityStructureType> {
        if let Some(t) = self.file.get(name) {
            return Ok(t.clone());
        }
        if let Ok(t) = self.library.get_entity_structure_type(name) {
            return Ok((*t).clone());
        }
        let where_ =
            if self.file.is_empty() { "esgm's library" } else { "esgm's library or the file" };
        let esgm = self.domain().with_context(|| {
            format!(
                "`{name}` is not in {where_}; give --config FILE, or a running domain (--domain)"
            )
        })?;
        esgm.get_entity_structure_type(name).map_err(Into::into)
    }

    /// The generated schema of `root`, every nested type looked up as [`Types::get`].
    pub fn schema(&mut self, root: &str) -> anyhow::Result<Schema> {
        // Schema::new's lookup cannot fail with a reason: find every type first.
        let mut found: BTreeMap<String, EntityStructureType> = BTreeMap::new();
        let mut todo = vec![root.to_owned()];
        while let Some(name) = todo.pop() {
            if found.contains_key(&name) {
                continue;
            }
            let t = self.get(&name)?;
            todo.extend(t.attributes.iter().filter_map(|a| a.element_type.clone()));
            found.insert(name, t);
        }
        Schema::new(root, |n| found.get(n).cloned())
            .with_context(|| format!("`{root}` has no ROS 2 message"))
    }
}

/// A type a standard ROS 2 message carries, if it has one.
fn standard(type_name: &str) -> Option<RosType> {
    RosType::for_esgm_type(type_name).ok()
}

/// `esgm-ros2 msg TYPE`: the `.msg` files of `type_name`, or the standard message it is
/// exported as.
pub fn print_msg(types: &mut Types, type_name: &str) -> anyhow::Result<()> {
    if let Some(standard) = standard(type_name) {
        println!("# {type_name} is exported as the standard message {}", standard.name());
        return Ok(());
    }
    let schema = types.schema(type_name)?;
    for (name, text) in schema.msg_files() {
        println!("# {PACKAGE}/msg/{name}.msg\n{text}");
    }
    Ok(())
}

/// `esgm-ros2 pkg DIR [TYPE…]`: writes the interface package `esgm_msgs` (package.xml,
/// CMakeLists.txt, `msg/`) into `dir` for `names` (none: every type of the system
/// file, else of the domain). Types a standard message carries are left out (said);
/// types that have no message are an error naming them, unless they were not asked for
/// by name (then said, and left out).
pub fn write_package(types: &mut Types, dir: &Path, names: &[String]) -> anyhow::Result<PathBuf> {
    let asked = !names.is_empty();
    let names = if asked {
        names.to_vec()
    } else if !types.declared().is_empty() {
        types.declared()
    } else {
        types.of_domain()?
    };
    let mut files: BTreeMap<String, String> = BTreeMap::new();
    for name in &names {
        if let Some(standard) = standard(name) {
            eprintln!(
                "{name}: exported as the standard message {}, not generated",
                standard.name()
            );
            continue;
        }
        let schema = match types.schema(name) {
            Ok(s) => s,
            Err(e) if !asked => {
                eprintln!("{name}: left out: {e:#}");
                continue;
            }
            Err(e) => return Err(e),
        };
        for (message, text) in schema.msg_files() {
            match files.get(&message) {
                Some(existing) if *existing != text => {
                    bail!("two definitions of {PACKAGE}/msg/{message}; this is a bug of esgm")
                }
                _ => {
                    files.insert(message, text);
                }
            }
        }
    }
    if files.is_empty() {
        bail!("no type to generate a message for (of {})", names.join(", "));
    }
    let package = dir.join(PACKAGE);
    let msg = package.join("msg");
    std::fs::create_dir_all(&msg).with_context(|| format!("cannot create {}", msg.display()))?;
    for (message, text) in &files {
        let path = msg.join(format!("{message}.msg"));
        std::fs::write(&path, text).with_context(|| format!("cannot write {}", path.display()))?;
    }
    let write = |name: &str, text: String| {
        let path = package.join(name);
        std::fs::write(&path, text).with_context(|| format!("cannot write {}", path.display()))
    };
    write("package.xml", package_xml())?;
    write("CMakeLists.txt", cmake_lists(files.keys()))?;
    Ok(package)
}

/// The packages every generated message may use (`field_type` in esgm-ros2msg).
const DEPENDENCIES: [&str; 3] = ["builtin_interfaces", "geometry_msgs", "std_msgs"];

fn package_xml() -> String {
    let depends: String =
        DEPENDENCIES.iter().map(|d| format!("  <depend>{d}</depend>\n")).collect();
    format!(
        r#"<?xml version="1.0"?>
<?xml-model href="http://download.ros.org/schema/package_format3.xsd" schematypens="http://www.w3.org/2001/XMLSchema"?>
<package format="3">
  <name>{PACKAGE}</name>
  <version>{version}</version>
  <description>The messages esgm exports its entity structure types as (written by esgm ros2 pkg): a structure with its std_msgs/Header, a nested frame as TypeFrame.</description>
  <maintainer email="esgm@localhost">esgm</maintainer>
  <license>MIT OR Apache-2.0</license>

  <buildtool_depend>ament_cmake</buildtool_depend>
  <buildtool_depend>rosidl_default_generators</buildtool_depend>
{depends}  <exec_depend>rosidl_default_runtime</exec_depend>
  <member_of_group>rosidl_interface_packages</member_of_group>

  <export>
    <build_type>ament_cmake</build_type>
  </export>
</package>
"#,
        version = env!("CARGO_PKG_VERSION"),
    )
}

fn cmake_lists<'a>(messages: impl Iterator<Item = &'a String>) -> String {
    let files: String = messages.map(|m| format!("  \"msg/{m}.msg\"\n")).collect();
    let finds: String =
        DEPENDENCIES.iter().map(|d| format!("find_package({d} REQUIRED)\n")).collect();
    format!(
        r#"cmake_minimum_required(VERSION 3.8)
project({PACKAGE})

find_package(ament_cmake REQUIRED)
find_package(rosidl_default_generators REQUIRED)
{finds}
rosidl_generate_interfaces(${{PROJECT_NAME}}
{files}  DEPENDENCIES {deps}
)

ament_export_dependencies(rosidl_default_runtime)
ament_package()
"#,
        deps = DEPENDENCIES.join(" "),
    )
}
