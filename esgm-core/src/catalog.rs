//! The catalog: what an ESGM knows by name (types, sensors, units, trajectories) and
//! the checks every runtime applies before creating a trajectory.
//!
//! Both runtimes use it: the in-process runtime next to its stores and workers, the
//! shared-memory coordinator as its registry, where sensors and units live in other
//! processes (their `host`). Keeping the rules here means a bad spec gets the same
//! error, with the same "did you mean", whichever runtime the program runs on.

use std::collections::BTreeMap;

use crate::esgm::{
    CreateError, InputType, LookupError, RegistrationError, TrajectoryInfo, TrajectorySource,
    TrajectorySpec,
};
use crate::filter::Filter;
use crate::policy::PolicyError;
use crate::sample::Sample;
use crate::type_check::TypeChecker;
use crate::type_registry::{TypeRegistry, TypeRegistryError, closest_name};
use crate::types::EntityStructureType;

/// A registered pull sensor.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct SensorRecord {
    /// The sensor's name.
    pub name: String,
    /// The registered type of the structures it produces.
    pub type_name: String,
    /// The process (location) that serves it; the in-process runtime uses its own name.
    pub host: String,
}

/// A registered computational unit.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct UnitRecord {
    /// The unit's name.
    pub name: String,
    /// The registered type of its output.
    pub type_name: String,
    /// What it declares about each input, in order.
    pub input_types: Vec<InputType>,
    /// The process (location) that runs it.
    pub host: String,
}

/// A spec that passed every check: the new trajectory's type checker and listing.
#[derive(Debug, Clone)]
pub struct Resolved {
    /// Checks the structures of the new trajectory.
    pub checker: TypeChecker,
    /// How the trajectory is listed (kind, type, source, inputs, policy).
    pub info: TrajectoryInfo,
}

/// A sampling window with the seed's zero rules: `from = 0` is now, `to = 0` forever;
/// otherwise both are non-negative and `from ≤ to`.
fn check_window(from: i64, to: i64) -> Result<(), PolicyError> {
    if from < 0 {
        return Err(PolicyError::illegal("from", from, "must be 0 (now) or positive"));
    }
    if to < 0 {
        return Err(PolicyError::illegal("to", to, "must be 0 (forever) or positive"));
    }
    if from != 0 && to != 0 && to < from {
        return Err(PolicyError::illegal("to", to, "must not be before from"));
    }
    Ok(())
}

/// Types, sensors, units and trajectories, by name.
#[derive(Debug, Clone, Default)]
pub struct Catalog {
    types: TypeRegistry,
    sensors: BTreeMap<String, SensorRecord>,
    units: BTreeMap<String, UnitRecord>,
    trajectories: BTreeMap<String, TrajectoryInfo>,
}

fn no_such_type(e: TypeRegistryError) -> CreateError {
    match e {
        TypeRegistryError::NoSuchEntityStructureType { name, suggestion } => {
            CreateError::NoSuchEntityStructureType { name, suggestion }
        }
        // Only lookups reach here; a definition error means a synthesized state type
        // broke a rule, reported as the type that could not be made.
        other => {
            CreateError::NoSuchEntityStructureType { name: other.to_string(), suggestion: None }
        }
    }
}

impl Catalog {
    /// A catalog holding `types` and nothing else.
    pub fn new(types: TypeRegistry) -> Self {
        Self { types, ..Self::default() }
    }

    /// The registered types.
    pub fn types(&self) -> &TypeRegistry {
        &self.types
    }

    /// The registered types, to create or destroy one.
    pub fn types_mut(&mut self) -> &mut TypeRegistry {
        &mut self.types
    }

    fn require_type(&self, type_name: &str) -> Result<(), RegistrationError> {
        match self.types.get_entity_structure_type(type_name) {
            Ok(_) => Ok(()),
            Err(TypeRegistryError::NoSuchEntityStructureType { name, suggestion }) => {
                Err(RegistrationError::NoSuchEntityStructureType { name, suggestion })
            }
            Err(other) => Err(RegistrationError::NoSuchEntityStructureType {
                name: other.to_string(),
                suggestion: None,
            }),
        }
    }

    /// Registers a sensor producing `type_name`, served by `host`.
    pub fn add_sensor(
        &mut self,
        name: &str,
        type_name: &str,
        host: &str,
    ) -> Result<(), RegistrationError> {
        self.require_type(type_name)?;
        if self.sensors.contains_key(name) {
            return Err(RegistrationError::SensorAlreadyExists { name: name.to_owned() });
        }
        let record = SensorRecord {
            name: name.to_owned(),
            type_name: type_name.to_owned(),
            host: host.to_owned(),
        };
        self.sensors.insert(name.to_owned(), record);
        Ok(())
    }

    /// Puts back a sensor exactly as a saved registry held it, without the checks of
    /// [`Catalog::add_sensor`]: a type may be destroyed while a sensor still names it
    /// (what was made with it keeps its copy), and a registry restored from its own
    /// saved state must hold what it held.
    pub fn restore_sensor(&mut self, record: SensorRecord) {
        self.sensors.insert(record.name.clone(), record);
    }

    /// Removes a sensor that no trajectory samples.
    pub fn remove_sensor(&mut self, name: &str) -> Result<SensorRecord, RegistrationError> {
        if !self.sensors.contains_key(name) {
            return Err(RegistrationError::NoSuchSensor {
                name: name.to_owned(),
                suggestion: closest_name(name, self.sensors.keys().map(String::as_str)),
            });
        }
        let users = self.users_of(crate::esgm::TrajectoryKind::Sampled, name);
        if !users.is_empty() {
            return Err(RegistrationError::InUse { name: name.to_owned(), users });
        }
        self.sensors.remove(name).ok_or_else(|| RegistrationError::NoSuchSensor {
            name: name.to_owned(),
            suggestion: None,
        })
    }

    /// A registered sensor.
    pub fn sensor(&self, name: &str) -> Option<&SensorRecord> {
        self.sensors.get(name)
    }

    /// Every registered sensor, by name.
    pub fn sensors(&self) -> impl Iterator<Item = &SensorRecord> {
        self.sensors.values()
    }

    /// Registers a unit producing `type_name` from inputs of `input_types`, run by `host`.
    pub fn add_unit(
        &mut self,
        name: &str,
        type_name: &str,
        input_types: Vec<InputType>,
        host: &str,
    ) -> Result<(), RegistrationError> {
        self.require_type(type_name)?;
        for t in &input_types {
            if let InputType::Type(t) = t {
                self.require_type(t)?;
            }
        }
        if self.units.contains_key(name) {
            return Err(RegistrationError::CompUnitAlreadyExists { name: name.to_owned() });
        }
        let record = UnitRecord {
            name: name.to_owned(),
            type_name: type_name.to_owned(),
            input_types,
            host: host.to_owned(),
        };
        self.units.insert(name.to_owned(), record);
        Ok(())
    }

    /// Puts back a unit exactly as a saved registry held it (see
    /// [`Catalog::restore_sensor`]).
    pub fn restore_unit(&mut self, record: UnitRecord) {
        self.units.insert(record.name.clone(), record);
    }

    /// Removes a unit that no trajectory uses.
    pub fn remove_unit(&mut self, name: &str) -> Result<UnitRecord, RegistrationError> {
        if !self.units.contains_key(name) {
            return Err(RegistrationError::NoSuchCompUnit {
                name: name.to_owned(),
                suggestion: closest_name(name, self.units.keys().map(String::as_str)),
            });
        }
        let mut users = self.users_of(crate::esgm::TrajectoryKind::Computed, name);
        users.extend(self.users_of(crate::esgm::TrajectoryKind::SampledFunction, name));
        if !users.is_empty() {
            return Err(RegistrationError::InUse { name: name.to_owned(), users });
        }
        self.units.remove(name).ok_or_else(|| RegistrationError::NoSuchCompUnit {
            name: name.to_owned(),
            suggestion: None,
        })
    }

    /// A registered unit.
    pub fn unit(&self, name: &str) -> Option<&UnitRecord> {
        self.units.get(name)
    }

    /// Every registered unit, by name.
    pub fn units(&self) -> impl Iterator<Item = &UnitRecord> {
        self.units.values()
    }

    fn users_of(&self, kind: crate::esgm::TrajectoryKind, source: &str) -> Vec<String> {
        self.trajectories
            .values()
            .filter(|t| t.kind == kind && t.source.as_deref() == Some(source))
            .map(|t| t.name.clone())
            .collect()
    }

    /// The error for an unknown trajectory name, with the closest existing name.
    pub fn no_such_trajectory(&self, name: &str) -> LookupError {
        LookupError::NoSuchEntityStructure {
            name: name.to_owned(),
            suggestion: closest_name(name, self.trajectories.keys().map(String::as_str)),
        }
    }

    /// The listing of the trajectory called `name`.
    pub fn trajectory(&self, name: &str) -> Result<&TrajectoryInfo, LookupError> {
        self.trajectories.get(name).ok_or_else(|| self.no_such_trajectory(name))
    }

    /// Every trajectory, by name.
    pub fn trajectories(&self) -> impl Iterator<Item = &TrajectoryInfo> {
        self.trajectories.values()
    }

    /// Records a created trajectory (replacing a re-pointed one).
    pub fn insert_trajectory(&mut self, info: TrajectoryInfo) {
        self.trajectories.insert(info.name.clone(), info);
    }

    /// Forgets a trajectory; its name can be reused.
    pub fn remove_trajectory(&mut self, name: &str) -> Result<TrajectoryInfo, LookupError> {
        match self.trajectories.remove(name) {
            Some(info) => Ok(info),
            None => Err(self.no_such_trajectory(name)),
        }
    }

    /// A chain of inputs from `inputs` back to `target`, if the existing trajectories
    /// form one (depth-first over the input graph).
    fn path_to(&self, target: &str, inputs: &[String]) -> Option<Vec<String>> {
        let mut stack: Vec<(String, Vec<String>)> =
            inputs.iter().map(|i| (i.clone(), vec![i.clone()])).collect();
        let mut seen = std::collections::HashSet::new();
        while let Some((name, path)) = stack.pop() {
            if name == target {
                return Some(path);
            }
            if !seen.insert(name.clone()) {
                continue;
            }
            if let Some(t) = self.trajectories.get(&name) {
                for i in &t.inputs {
                    let mut p = path.clone();
                    p.push(i.clone());
                    stack.push((i.clone(), p));
                }
            }
        }
        None
    }

    /// The unit `unit`, checked against the inputs (name, type) it would be given.
    fn unit_for(
        &self,
        unit: &str,
        inputs: &[(String, String)],
    ) -> Result<&UnitRecord, CreateError> {
        let record = self.units.get(unit).ok_or_else(|| CreateError::NoSuchCompUnit {
            name: unit.to_owned(),
            suggestion: closest_name(unit, self.units.keys().map(String::as_str)),
        })?;
        if record.input_types.len() != inputs.len() {
            return Err(CreateError::WrongInputCount {
                unit: unit.to_owned(),
                expected: record.input_types.len(),
                found: inputs.len(),
            });
        }
        for (position, (declared, (input, actual))) in
            record.input_types.iter().zip(inputs).enumerate()
        {
            if !declared.accepts(actual) {
                return Err(CreateError::InvalidInput {
                    unit: unit.to_owned(),
                    input: input.clone(),
                    position,
                    expected: declared.to_string(),
                    actual: actual.clone(),
                });
            }
        }
        Ok(record)
    }

    fn input_type(&self, name: &str) -> Result<&str, CreateError> {
        match self.trajectories.get(name) {
            Some(t) => Ok(&t.type_name),
            None => Err(CreateError::NoSuchEntityStructure {
                name: name.to_owned(),
                suggestion: closest_name(name, self.trajectories.keys().map(String::as_str)),
            }),
        }
    }

    /// An average or median merge needs every attribute of the input's type to have a
    /// mean or a median (numbers, times, geometric values, nested frames; an average
    /// also number sequences): a string or an image would only take the last value,
    /// so the rule is refused here, naming the attribute.
    fn check_merge_rule(
        &self,
        input: &str,
        type_name: &str,
        rule: crate::approximation::MergeRule,
    ) -> Result<(), CreateError> {
        use crate::approximation::MergeRule;
        use crate::value::ValueSort;
        let what = match rule {
            MergeRule::Average => "mean",
            MergeRule::Median => "median",
            MergeRule::KeepFirst | MergeRule::KeepLast => return Ok(()),
        };
        let Ok(ty) = self.types.get_entity_structure_type(type_name) else { return Ok(()) };
        for a in &ty.attributes {
            let ok = a.sort.is_numeric()
                || a.sort == ValueSort::EntityFrame
                || (rule == MergeRule::Average
                    && matches!(a.sort, ValueSort::LongSeq | ValueSort::DoubleSeq));
            if !ok {
                let reason = format!(
                    "attribute `{}` of `{input}` is a {:?}, which has no {what}; merge it with \
                     keep-first or keep-last",
                    a.name, a.sort
                );
                return Err(PolicyError::illegal("merge", format!("{rule:?}"), &reason).into());
            }
        }
        Ok(())
    }

    fn checker(&self, type_name: &str) -> Result<TypeChecker, CreateError> {
        TypeChecker::new(&self.types, type_name).map_err(no_such_type)
    }

    /// A checker for an operator's state type (one frame per input, named after the
    /// input), built on a copy of the registry so the synthesized type is not listed.
    fn state_checker(
        &self,
        name: &str,
        inputs: &[(String, String)],
        member_times: bool,
    ) -> Result<TypeChecker, CreateError> {
        let mut ty = EntityStructureType::new(format!("{name}:state"));
        for (input, type_name) in inputs {
            ty = ty.frame(input.clone(), type_name.clone());
        }
        if member_times {
            ty = crate::operators::sync::with_member_times(ty);
        }
        let mut registry = self.types.clone();
        let key = ty.name.clone();
        // A state type left from before is replaced; none there is fine too.
        let _absent_is_fine = registry.destroy_entity_structure_type(&key);
        registry.create_entity_structure_type(key.clone(), ty).map_err(no_such_type)?;
        TypeChecker::new(&registry, &key).map_err(no_such_type)
    }

    /// Applies every check a trajectory must pass before it exists: the name is free
    /// (or `replace` is set), everything it names exists, inputs fit the unit or
    /// operator, the policy is legal and its filter type-checks.
    pub fn resolve(&self, spec: &TrajectorySpec) -> Result<Resolved, CreateError> {
        let name = spec.name.clone();
        if self.trajectories.contains_key(&name) && !spec.replace {
            return Err(CreateError::EntityStructureAlreadyExists { name });
        }
        let input_names = spec.inputs();
        let inputs: Vec<(String, String)> = input_names
            .iter()
            .map(|n| self.input_type(n).map(|t| (n.clone(), t.to_owned())))
            .collect::<Result<_, _>>()?;
        let operator = matches!(
            spec.source,
            TrajectorySource::Sync { .. }
                | TrajectorySource::Merge { .. }
                | TrajectorySource::SampledGenerators { .. }
        );
        if operator && inputs.is_empty() {
            return Err(CreateError::NoInputs { name });
        }
        if let TrajectorySource::Sampled { from, to, .. }
        | TrajectorySource::SampledGenerators { from, to, .. } = &spec.source
        {
            check_window(*from, *to)?;
        }
        let (checker, source) = match &spec.source {
            TrajectorySource::Primitive { type_name } => (self.checker(type_name)?, None),
            TrajectorySource::Sampled { sensor, sample_period, .. } => {
                let record = self.sensors.get(sensor).ok_or_else(|| CreateError::NoSuchSensor {
                    name: sensor.clone(),
                    suggestion: closest_name(sensor, self.sensors.keys().map(String::as_str)),
                })?;
                if *sample_period <= 0 {
                    return Err(PolicyError::illegal(
                        "sample_period",
                        sample_period,
                        "must be positive",
                    )
                    .into());
                }
                (self.checker(&record.type_name)?, Some(sensor.clone()))
            }
            TrajectorySource::Computed { unit, .. } => {
                let record = self.unit_for(unit, &inputs)?;
                (self.checker(&record.type_name)?, Some(unit.clone()))
            }
            TrajectorySource::Merge { .. } => {
                let first = inputs[0].1.clone();
                for (position, (input, actual)) in inputs.iter().enumerate() {
                    if *actual != first {
                        return Err(CreateError::InvalidInput {
                            unit: "merge".into(),
                            input: input.clone(),
                            position,
                            expected: format!(
                                "type `{first}` (all inputs of a merge share one type)"
                            ),
                            actual: actual.clone(),
                        });
                    }
                }
                (self.checker(&first)?, Some("merge".into()))
            }
            TrajectorySource::Sync { policy, .. } => {
                // Validate the operator's settings now, not when the worker starts.
                policy.create::<Sample>(inputs.len())?;
                (self.state_checker(&name, &inputs, true)?, Some("sync".into()))
            }
            TrajectorySource::SampledGenerators { sample_period, unit, inputs: gens, .. } => {
                for ((input, type_name), (_, g)) in inputs.iter().zip(gens) {
                    self.check_merge_rule(input, type_name, g.merge)?;
                }
                if *sample_period <= 0 {
                    return Err(PolicyError::illegal(
                        "sample_period",
                        sample_period,
                        "must be positive",
                    )
                    .into());
                }
                match unit {
                    Some(unit) => {
                        let record = self.unit_for(unit, &inputs)?;
                        (self.checker(&record.type_name)?, Some(unit.clone()))
                    }
                    None if inputs.len() == 1 => {
                        (self.checker(&inputs[0].1)?, Some("generator".into()))
                    }
                    None => (self.state_checker(&name, &inputs, false)?, Some("state".into())),
                }
            }
        };
        if let Some(old) = self.trajectories.get(&name) {
            if old.type_name != checker.type_name() {
                return Err(CreateError::TypeChange {
                    name,
                    old: old.type_name.clone(),
                    new: checker.type_name().to_owned(),
                });
            }
            if let Some(path) = self.path_to(&name, &input_names) {
                return Err(CreateError::Cycle { name, path });
            }
        }
        spec.policy.validate()?;
        if let Some(src) = &spec.policy.filter {
            Filter::compile(src, &checker).map_err(PolicyError::from)?;
        }
        let info = TrajectoryInfo {
            name,
            kind: spec.kind(),
            type_name: checker.type_name().to_owned(),
            source,
            inputs: input_names,
            policy: spec.policy.clone(),
        };
        Ok(Resolved { checker, info })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::policy::FluentStreamPolicy;

    #[test]
    fn hosts_are_recorded_and_specs_resolved_without_a_runtime() {
        let mut c = Catalog::new(TypeRegistry::with_library());
        c.add_sensor("camera", "Image", "camera-process").unwrap();
        assert_eq!(c.sensor("camera").map(|s| s.host.as_str()), Some("camera-process"));
        c.add_unit("BlobDetection", "BlobSeq", vec!["Image".into()], "cu-worker-1").unwrap();
        let images =
            c.resolve(&TrajectorySpec::sampled("images", "camera", 1_000).unwrap()).unwrap();
        assert_eq!(images.info.type_name, "Image");
        c.insert_trajectory(images.info);
        let blobs =
            c.resolve(&TrajectorySpec::computed("blobs", "BlobDetection", ["images"])).unwrap();
        assert_eq!(
            (blobs.info.type_name.as_str(), blobs.info.inputs.clone()),
            ("BlobSeq", vec!["images".to_owned()])
        );
        // The same rules as the in-process runtime: in use, unknown, illegal filter.
        assert!(matches!(c.remove_sensor("camera"), Err(RegistrationError::InUse { .. })));
        assert!(matches!(
            c.resolve(&TrajectorySpec::computed("x", "BlobDetection", ["imagez"])),
            Err(CreateError::NoSuchEntityStructure { suggestion: Some(_), .. })
        ));
        let bad_filter = TrajectorySpec::primitive("b", "Blob")
            .policy(FluentStreamPolicy::default().filter("szie > 3"));
        assert!(matches!(
            c.resolve(&bad_filter),
            Err(CreateError::IllegalPolicy(PolicyError::IllegalFilter(_)))
        ));
        assert!(c.resolve(&TrajectorySpec::primitive("images", "Image")).is_err(), "name taken");
        assert!(c.resolve(&TrajectorySpec::primitive("images", "Image").replace()).is_ok());
        // Sampling windows follow the seed's zero rules.
        for (from, to) in [(-1, 0), (0, -5), (200, 100)] {
            let spec = TrajectorySpec::sampled("w", "camera", 10).unwrap().between(from, to);
            assert!(matches!(c.resolve(&spec), Err(CreateError::IllegalPolicy(_))), "{from} {to}");
        }
        // Re-pointing keeps the type and may not loop back to itself.
        c.insert_trajectory(blobs.info);
        assert!(matches!(
            c.resolve(&TrajectorySpec::primitive("images", "Blob").replace()),
            Err(CreateError::TypeChange { .. })
        ));
        c.add_unit("Copy", "Image", vec!["Image".into()], "h").unwrap();
        let err = c
            .resolve(&TrajectorySpec::computed("images", "Copy", ["images"]).replace())
            .unwrap_err();
        assert!(matches!(err, CreateError::Cycle { .. }), "{err}");
    }
}
