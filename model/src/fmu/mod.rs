//! Models users bring: FMUs (FMI 2.0 and 3.0, Model Exchange and Co-Simulation).
//!
//! An `.fmu` is a zip archive holding `modelDescription.xml` and a shared library per
//! platform. [`open`] reads one, names it by its content hash, unpacks it once into a cache
//! folder and registers it as a model beside the hosted ones: its real parameters (causality
//! `parameter`) are the model's parameters, with their start values, units and min/max; its
//! outputs, then its other real variables, are the model's outputs; the measurement effects
//! (offset, gain, delay, lag) apply to them as to every model ([`crate::effects`]); its
//! inputs (causality `input`: Real, Integer, Boolean) are the model's inputs, set from the
//! signals of a [`crate::Run`] as `run.rs` says. The
//! model's name is `<modelIdentifier>.<me|cs>@<first 12 hex digits of the hash>`, so that
//! two different FMUs never share cached evaluations.
//!
//! The FMI C API is called through `libloading` with the standard's signatures declared in
//! [`ffi`] (not the `fmi` crate: its bindings need libclang at build time and its logger
//! goes to the `log` crate, where a failed simulation could not pick up the FMU's own
//! messages). Instances are reused between evaluations: each simulation takes an idle
//! instance (one per thread that simulates at once), `fmi*Reset`s it and initialises it
//! again; see [`run`] for the integration.
//!
//! Archives are read and unpacked within [`archive::Limits`] (sizes, inflated and not,
//! and the number of entries; see [`crate::limits`]), counting what is inflated rather
//! than believing the archive's headers.
//!
//! Loading an FMU runs its native code. When [`isolate_with`] names a host program (the
//! `calib` binary does, with its hidden `fmu-host` subcommand), every instance lives in a
//! child process instead ([`host`]): a crash, an abort or a hang there is a failed
//! simulation with the FMU's messages, and the next simulation starts a fresh child.

pub mod archive;
#[cfg(target_os = "linux")]
pub mod contain;
mod description;
mod ffi;
pub mod host;
mod run;

pub use description::{Description, FmiVersion, Interface, Kind, Variable};

use crate::effects::WithOutputEffects;
use crate::inputs::Inputs;
use crate::model::{
    check_request, InputSpec, Model, ModelInfo, OutputSpec, ParameterSpec, SimulationError,
    SolverOptions, Trajectory,
};
use crate::Run;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, OnceLock};

/// Why an FMU cannot be used, or why a call into it failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FmuError {
    #[error("cannot read the FMU: {0}")]
    Archive(String),
    /// Past one of the limits of [`archive::Limits`], which the message names.
    #[error("the FMU is refused: {0}")]
    Refused(String),
    #[error("modelDescription.xml: {0}")]
    Description(String),
    #[error("{0}")]
    Binary(String),
    #[error("{function} returned {status}{}", log_suffix(log))]
    Call {
        function: String,
        status: &'static str,
        log: Vec<String>,
    },
    #[error("the event iteration did not settle in {0} passes")]
    Loop(usize),
    #[error("{0}")]
    Host(String),
}

fn log_suffix(log: &[String]) -> String {
    if log.is_empty() {
        String::new()
    } else {
        format!("; the FMU says: {}", log.join(" | "))
    }
}

/// Does `name` look like an FMU path rather than a hosted model's name?
pub fn is_fmu_path(name: &str) -> bool {
    name.to_ascii_lowercase().ends_with(".fmu")
}

/// The content hash an FMU is named by (BLAKE3 of the archive's bytes).
pub fn content_hash(bytes: &[u8]) -> [u8; 32] {
    *blake3::hash(bytes).as_bytes()
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// An FMU unpacked and described, ready to simulate.
pub struct FmuModel {
    info: ModelInfo,
    description: Description,
    interface: Interface,
    identifier: String,
    dir: PathBuf,
    parameter_vrs: Vec<u32>,
    output_refs: Vec<(Kind, u32)>,
    input_refs: Vec<run::InputRef>,
    runner: Runner,
}

enum Runner {
    /// Instances in this process.
    Local(Local),
    /// Instances in child processes.
    Isolated(host::Hosts),
}

/// The real parameters a campaign may set, with their bounds (unbounded in the model
/// description: unbounded here; a campaign's bounds are always finite) and start values.
fn parameter_specs(description: &Description) -> Vec<ParameterSpec> {
    description
        .parameters()
        .map(|v| {
            // Unbounded in the model description: unbounded here (a campaign's bounds
            // are always finite).
            let min = v.min.unwrap_or(f64::NEG_INFINITY);
            let max = v.max.unwrap_or(f64::INFINITY);
            ParameterSpec {
                name: v.name.clone(),
                unit: v.unit.clone(),
                default: v.start.unwrap_or(0.0).clamp(min, max),
                min,
                max,
                description: v.description.clone(),
            }
        })
        .collect()
}

/// The observable variables as outputs (a non-output's causality in its description).
fn output_specs(observables: &[&description::Variable]) -> Vec<OutputSpec> {
    observables
        .iter()
        .map(|v| OutputSpec {
            name: v.name.clone(),
            unit: v.unit.clone(),
            description: if v.causality == "output" {
                v.description.clone()
            } else {
                format!("({}) {}", v.causality, v.description)
                    .trim_end()
                    .to_string()
            },
        })
        .collect()
}

/// The input variables, each described with how it is held between samples and what it is
/// when undriven.
fn input_specs(description: &Description) -> Vec<InputSpec> {
    description
        .inputs()
        .map(|v| {
            let undriven = match (v.kind, v.start) {
                (Kind::Boolean, Some(s)) => format!("{}", s != 0.0),
                (_, Some(s)) => format!("{s}"),
                (_, None) => "its start value".to_string(),
            };
            let held = match v.kind {
                Kind::Real if v.variability != "discrete" => String::new(),
                Kind::Real => "discrete, held between samples; ".to_string(),
                Kind::Integer => "integer, held between samples and rounded; ".to_string(),
                Kind::Boolean => "boolean, held between samples, true when non-zero; ".to_string(),
            };
            InputSpec {
                name: v.name.clone(),
                unit: v.unit.clone(),
                description: if v.description.is_empty() {
                    format!("{held}undriven: {undriven}")
                } else {
                    format!("{} ({held}undriven: {undriven})", v.description)
                },
            }
        })
        .collect()
}

/// The interface to run the FMU through (`interface`, by default Model Exchange when the FMU
/// has it, else Co-Simulation) and its model identifier; an error when the FMU lacks it.
fn interface_of(
    description: &Description,
    interface: Option<Interface>,
) -> Result<(Interface, String), FmuError> {
    let interface = match interface {
        Some(i) => i,
        None if description.model_exchange.is_some() => Interface::ModelExchange,
        None => Interface::CoSimulation,
    };
    let identifier = match interface {
        Interface::ModelExchange => description.model_exchange.clone(),
        Interface::CoSimulation => description.co_simulation.clone(),
    }
    .ok_or_else(|| {
        FmuError::Description(format!("the FMU does not support {}", interface.name()))
    })?;
    Ok((interface, identifier))
}

/// How each input variable is set: its kind, value reference, and whether it is held between
/// samples (every non-real, and the discrete reals).
fn input_refs(description: &Description) -> Vec<run::InputRef> {
    description
        .inputs()
        .map(|v| run::InputRef {
            kind: v.kind,
            vr: v.value_reference,
            discrete: v.kind != Kind::Real || v.variability == "discrete",
        })
        .collect()
}

/// The model's name, `<modelIdentifier>.<me|cs>@<first 12 hex digits of the hash>`: two
/// different FMUs never share one.
fn model_name(identifier: &str, interface: Interface, hash: &[u8; 32]) -> String {
    let kind = match interface {
        Interface::ModelExchange => "me",
        Interface::CoSimulation => "cs",
    };
    format!("{identifier}.{kind}@{}", &hex(hash)[..12])
}

/// The model's description: the FMU's name, FMI version, interface and own description.
fn model_description(description: &Description, interface: Interface) -> String {
    format!(
        "FMU {} (FMI {}, {}): {}",
        description.model_name,
        match description.version {
            FmiVersion::V2 => "2.0",
            FmiVersion::V3 => "3.0",
        },
        interface.name(),
        description.description
    )
}

struct Local {
    library: OnceLock<Result<Arc<ffi::Library>, FmuError>>,
    idle: Mutex<Vec<ffi::Instance>>,
}

impl FmuModel {
    /// Describe the FMU unpacked at `dir` (content hash `hash`), to run through `interface`
    /// (default: Model Exchange when the FMU has it, else Co-Simulation).
    fn new(
        dir: PathBuf,
        hash: &[u8; 32],
        interface: Option<Interface>,
        isolated: bool,
    ) -> Result<Self, FmuError> {
        let xml = archive::read_description(&dir)?;
        let description = Description::parse(&xml)?;
        let (interface, identifier) = interface_of(&description, interface)?;
        let parameters = parameter_specs(&description);
        let parameter_vrs = description
            .parameters()
            .map(|v| v.value_reference)
            .collect();
        let observables = description.observables();
        let outputs = output_specs(&observables);
        let output_refs = observables
            .iter()
            .map(|v| (v.kind, v.value_reference))
            .collect();
        let inputs = input_specs(&description);
        let input_refs = input_refs(&description);
        let info = ModelInfo {
            name: model_name(&identifier, interface, hash),
            version: 1,
            description: model_description(&description, interface),
            parameters,
            outputs,
            effects: Vec::new(),
            inputs,
        };
        let runner = if isolated {
            Runner::Isolated(host::Hosts::new(dir.clone(), interface, identifier.clone()))
        } else {
            Runner::Local(Local {
                library: OnceLock::new(),
                idle: Mutex::new(Vec::new()),
            })
        };
        Ok(Self {
            info,
            description,
            interface,
            identifier,
            dir,
            parameter_vrs,
            output_refs,
            input_refs,
            runner,
        })
    }

    pub fn description(&self) -> &Description {
        &self.description
    }

    pub fn interface(&self) -> Interface {
        self.interface
    }

    /// Median cost of a fresh instance (instantiate and free) and of a reset, over `repeat`
    /// tries each, in this process: why instances are reused with a reset.
    pub fn instance_costs(
        &self,
        repeat: usize,
    ) -> Result<(std::time::Duration, std::time::Duration), FmuError> {
        let library = Arc::new(ffi::Library::load(
            &self.dir,
            self.description.version,
            self.interface,
            &self.identifier,
            &self.description.token,
        )?);
        let median = |mut v: Vec<std::time::Duration>| {
            v.sort();
            v[v.len() / 2]
        };
        let mut fresh = Vec::with_capacity(repeat);
        for _ in 0..repeat.max(1) {
            let start = std::time::Instant::now();
            drop(library.instantiate()?);
            fresh.push(start.elapsed());
        }
        let mut instance = library.instantiate()?;
        let mut reset = Vec::with_capacity(repeat);
        for _ in 0..repeat.max(1) {
            let start = std::time::Instant::now();
            instance.reset()?;
            reset.push(start.elapsed());
        }
        Ok((median(fresh), median(reset)))
    }

    /// Free the instances kept for the next simulations in this process (their helper
    /// processes were killed with the simulation that started them).
    pub fn forget_idle_instances(&self) {
        if let Runner::Local(local) = &self.runner {
            local.idle.lock().unwrap_or_else(|e| e.into_inner()).clear();
        }
    }

    /// Simulate in this process, whatever the runner (the child process's side).
    fn simulate_here(
        &self,
        local: &Local,
        params: &[f64],
        grid: &[f64],
        outputs: &[usize],
        options: &SolverOptions,
        inputs: &Inputs,
    ) -> Result<Trajectory, SimulationError> {
        let library = local
            .library
            .get_or_init(|| {
                ffi::Library::load(
                    &self.dir,
                    self.description.version,
                    self.interface,
                    &self.identifier,
                    &self.description.token,
                )
                .map(Arc::new)
            })
            .as_ref()
            .map_err(|e| SimulationError::Failed {
                time: 0.0,
                reason: e.to_string(),
            })?;
        let reused = local.idle.lock().unwrap_or_else(|e| e.into_inner()).pop();
        let (mut instance, fresh) = match reused {
            Some(instance) => (instance, false),
            None => (
                library.instantiate().map_err(|e| SimulationError::Failed {
                    time: 0.0,
                    reason: e.to_string(),
                })?,
                true,
            ),
        };
        let selected: Vec<(Kind, u32)> = outputs.iter().map(|&o| self.output_refs[o]).collect();
        let outputs = run::Outputs::new(&selected);
        let plan = run::Plan {
            interface: self.interface,
            parameter_vrs: &self.parameter_vrs,
            parameters: &params[..self.parameter_vrs.len()],
            outputs: &outputs,
            states: self.description.continuous_states,
            indicators: self.description.event_indicators,
            inputs: &run::Driven::new(&self.input_refs, inputs),
        };
        let result = run::simulate(&mut instance, fresh, &plan, grid, options);
        // An instance that failed is dropped (freed) rather than reset for the next run.
        if result.is_ok() {
            local
                .idle
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .push(instance);
        }
        result
    }
}

impl FmuModel {
    /// The relative tolerance of the FMU's `DefaultExperiment`, when it gives a usable one.
    pub fn own_tolerance(&self) -> Option<f64> {
        self.description
            .default_tolerance
            .filter(|t| crate::limits::RTOL.contains(t))
    }
}

impl Model for FmuModel {
    fn info(&self) -> &ModelInfo {
        &self.info
    }

    /// calib's defaults, except what the FMU's `DefaultExperiment` gives: its tolerance (the
    /// integrator's rtol for Model Exchange, with atol a hundredth of it as `calib simulate
    /// --rtol` sets; the tolerance the FMU is told for Co-Simulation) and, for
    /// Co-Simulation, its step size as the communication step.
    fn default_options(&self) -> SolverOptions {
        let mut options = SolverOptions::default();
        if let Some(rtol) = self.own_tolerance() {
            options.rtol = rtol;
            options.atol = rtol / 100.0;
        }
        if self.interface == Interface::CoSimulation {
            options.communication_step = self
                .description
                .default_step_size
                .filter(|h| h.is_finite() && *h > 0.0);
        }
        options
    }

    /// The `DefaultExperiment`'s stop time, when it gives one after its start.
    fn default_stop_time(&self) -> f64 {
        let start = self.description.default_start_time.unwrap_or(0.0);
        self.description
            .default_stop_time
            .filter(|t| t.is_finite() && *t > start)
            .unwrap_or(crate::model::DEFAULT_STOP_TIME)
    }

    fn tolerance_origin(&self) -> &'static str {
        if self.own_tolerance().is_some() {
            "the FMU's default experiment"
        } else {
            "calib's default"
        }
    }

    /// The FMU's inputs (causality `input`) set from the signals as the standard's
    /// simulation algorithms do (see `run.rs`); inputs without a signal keep their start
    /// values.
    fn simulate(&self, run: &Run) -> Result<Trajectory, SimulationError> {
        run.refuse_forces(self.info())?;
        let Run {
            params,
            grid,
            outputs,
            options,
            inputs,
            ..
        } = *run;
        check_request(&self.info, params, grid, outputs)?;
        let stop = grid.last().copied().unwrap_or(options.start_time);
        inputs
            .check(&self.info, options.start_time, stop.max(options.start_time))
            .map_err(SimulationError::InvalidInput)?;
        match &self.runner {
            Runner::Local(local) => {
                self.simulate_here(local, params, grid, outputs, options, inputs)
            }
            Runner::Isolated(hosts) => hosts.simulate(params, grid, outputs, options, inputs),
        }
    }
}

/// The program (and its leading arguments) that hosts FMU instances in child processes.
#[derive(Debug, Clone)]
pub struct HostCommand {
    pub program: PathBuf,
    pub args: Vec<String>,
}

static HOST: OnceLock<HostCommand> = OnceLock::new();

/// Run every FMU opened from now on in child processes started as `command DIR INTERFACE`.
/// Without it (library tests, the child itself) instances live in this process.
pub fn isolate_with(command: HostCommand) {
    let _ = HOST.set(command);
}

pub(crate) fn host_command() -> Option<&'static HostCommand> {
    HOST.get()
}

struct Registered {
    hash: [u8; 32],
    interface: Interface,
    /// Opened without naming an interface: the FMU's default (Model Exchange when offered).
    default: bool,
    /// Where the archive is kept (read again to send it to a worker): the file it was
    /// opened from, or a worker's FMU cache. Never the bytes themselves, which would stay
    /// in memory as long as the process.
    archive: Option<PathBuf>,
    model: &'static dyn Model,
}

fn registry() -> &'static Mutex<Vec<Registered>> {
    static REGISTRY: OnceLock<Mutex<Vec<Registered>>> = OnceLock::new();
    REGISTRY.get_or_init(|| Mutex::new(Vec::new()))
}

/// The FMU at `path` as a model (with the measurement effects of its outputs). Opening the
/// same content again returns the same model.
pub fn open(path: &Path, interface: Option<Interface>) -> Result<&'static dyn Model, FmuError> {
    let limits = archive::Limits::default();
    let bytes = archive::read(path, &limits)?;
    let opened = open_in(&bytes, interface, &unpack_root(), &limits)?;
    remember_archive(&content_hash(&bytes), path);
    Ok(opened)
}

/// The FMU whose archive is `bytes`, as [`open`] (within the default limits, unpacked
/// where `CALIB_FMU_DIR` says).
pub fn open_bytes(
    bytes: &[u8],
    interface: Option<Interface>,
) -> Result<&'static dyn Model, FmuError> {
    open_in(
        bytes,
        interface,
        &unpack_root(),
        &archive::Limits::default(),
    )
}

/// The FMU whose archive is `bytes`, unpacked into `root` within `limits`, as [`open`].
pub fn open_in(
    bytes: &[u8],
    interface: Option<Interface>,
    root: &Path,
    limits: &archive::Limits,
) -> Result<&'static dyn Model, FmuError> {
    let hash = content_hash(bytes);
    let mut registry = registry().lock().unwrap_or_else(|e| e.into_inner());
    if let Some(r) = registry.iter().find(|r| {
        r.hash == hash
            && match interface {
                Some(i) => i == r.interface,
                // Only an FMU opened by default answers for the default: one opened for
                // Co-Simulation first must not stand in for its Model Exchange.
                None => r.default,
            }
    }) {
        return Ok(r.model);
    }
    let dir = archive::unpack(bytes, &hex(&hash), root, limits)?;
    let model = FmuModel::new(dir, &hash, interface, host_command().is_some())?;
    let default = interface.is_none();
    let interface = model.interface;
    let archive = registry
        .iter()
        .find(|r| r.hash == hash)
        .and_then(|r| r.archive.clone());
    let model: &'static dyn Model = Box::leak(Box::new(WithOutputEffects::new(model)));
    registry.push(Registered {
        hash,
        interface,
        default,
        archive,
        model,
    });
    Ok(model)
}

/// Every interface the FMU whose archive is `bytes` offers, opened (see [`open_in`]).
pub fn open_all_in(
    bytes: &[u8],
    root: &Path,
    limits: &archive::Limits,
) -> Result<Vec<&'static dyn Model>, FmuError> {
    let first = open_in(bytes, None, root, limits)?;
    let mut models = vec![first];
    if first.info().name.contains(".me@") {
        // Model Exchange is the default; Co-Simulation may be there too.
        if let Ok(cs) = open_in(bytes, Some(Interface::CoSimulation), root, limits) {
            models.push(cs);
        }
    }
    Ok(models)
}

/// Every interface the FMU whose archive is `bytes` offers, as [`open_bytes`].
pub fn open_all(bytes: &[u8]) -> Result<Vec<&'static dyn Model>, FmuError> {
    open_all_in(bytes, &unpack_root(), &archive::Limits::default())
}

/// The archive of the FMU whose content hash is `hash` is kept at `path` (read again by
/// [`archive_of`]).
pub fn remember_archive(hash: &[u8; 32], path: &Path) {
    for r in registry()
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .iter_mut()
        .filter(|r| r.hash == *hash)
    {
        r.archive = Some(path.to_path_buf());
    }
}

/// The content hash of the FMU model registered under `name`.
pub fn hash_of(name: &str) -> Option<[u8; 32]> {
    registered(name, |r| r.hash)
}

/// `what` of the FMU model registered under `name`, read under the registry's lock.
fn registered<T>(name: &str, what: impl FnOnce(&Registered) -> T) -> Option<T> {
    registry()
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .iter()
        .find(|r| r.model.info().name == name)
        .map(what)
}

/// The archive and content hash of the FMU model registered under `name`, to send it to a
/// worker: read again from where it is kept, and only when its content is still the one
/// opened.
pub fn archive_of(name: &str) -> Option<([u8; 32], Arc<Vec<u8>>)> {
    let (hash, path) = registered(name, |r| (r.hash, r.archive.clone()))?;
    let path = path?;
    match archive::read(&path, &archive::Limits::default()) {
        Ok(bytes) if content_hash(&bytes) == hash => Some((hash, Arc::new(bytes))),
        Ok(_) => {
            tracing::warn!(path = %path.display(), "the FMU's archive changed since it was opened");
            None
        }
        Err(e) => {
            tracing::warn!(path = %path.display(), "the FMU's archive cannot be read again: {e}");
            None
        }
    }
}

/// The interface an FMU model's name says it runs through (`….me@…` or `….cs@…`).
pub fn interface_in_name(name: &str) -> Option<Interface> {
    let (head, _) = name.rsplit_once('@')?;
    if head.ends_with(".me") {
        Some(Interface::ModelExchange)
    } else if head.ends_with(".cs") {
        Some(Interface::CoSimulation)
    } else {
        None
    }
}

/// The FMU model registered under `name` (see the module documentation).
pub fn find(name: &str) -> Option<&'static dyn Model> {
    registered(name, |r| r.model)
}

/// The FMU at `path` with its instances in this process whatever [`isolate_with`] says, and
/// not registered (for benchmarks).
pub fn open_local(path: &Path, interface: Option<Interface>) -> Result<FmuModel, FmuError> {
    open_unregistered(path, interface, false)
}

/// The FMU at `path`, not registered: its instances in child processes when `isolated`
/// (and [`isolate_with`] named a host program), else in this process. Dropping it stops
/// its child processes.
pub fn open_unregistered(
    path: &Path,
    interface: Option<Interface>,
    isolated: bool,
) -> Result<FmuModel, FmuError> {
    let limits = archive::Limits::default();
    let bytes = archive::read(path, &limits)?;
    let hash = content_hash(&bytes);
    let dir = archive::unpack(&bytes, &hex(&hash), &unpack_root(), &limits)?;
    FmuModel::new(dir, &hash, interface, isolated && host_command().is_some())
}

/// Open an FMU already unpacked at `dir`, in this process (the child process's side).
pub fn open_unpacked(dir: &Path, interface: Interface) -> Result<FmuModel, FmuError> {
    FmuModel::new(dir.to_path_buf(), &[0; 32], Some(interface), false)
}

fn unpack_root() -> PathBuf {
    std::env::var_os("CALIB_FMU_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| std::env::temp_dir().join("calib-fmu"))
}
