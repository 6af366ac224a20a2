//! FMU archives that lie or inflate: refused with a message naming the limit, while
//! inflating and before anything large is allocated; a worker refusing them keeps serving,
//! leaves no staging folder behind and does not keep uploads in memory. Every allocation of
//! this test program is counted, so that "bounded memory" is measured, not assumed.

#[path = "../../model/tests/common/zips.rs"]
mod zips;

use calib_model::fmu::archive::{self, Limits};
use calib_model::fmu::{Description, FmuError};
use calib_proto::v1 as proto;
use calib_proto::v1::simulator_client::SimulatorClient;
use calib_worker::service::{serve_worker, WorkerConfig};
use proptest::prelude::*;
use std::alloc::{GlobalAlloc, Layout, System};
use std::io::Write;
use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;
use zips::{stored_zip64, Lies, DESCRIPTION};

/// The system allocator, counting the bytes allocated now and the most at once.
struct Counting;

static LIVE: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let p = System.alloc(layout);
        if !p.is_null() {
            let now = LIVE.fetch_add(layout.size(), Ordering::Relaxed) + layout.size();
            PEAK.fetch_max(now, Ordering::Relaxed);
        }
        p
    }
    unsafe fn dealloc(&self, p: *mut u8, layout: Layout) {
        System.dealloc(p, layout);
        LIVE.fetch_sub(layout.size(), Ordering::Relaxed);
    }
    unsafe fn realloc(&self, p: *mut u8, layout: Layout, size: usize) -> *mut u8 {
        let q = System.realloc(p, layout, size);
        if !q.is_null() {
            if size >= layout.size() {
                let now =
                    LIVE.fetch_add(size - layout.size(), Ordering::Relaxed) + size - layout.size();
                PEAK.fetch_max(now, Ordering::Relaxed);
            } else {
                LIVE.fetch_sub(layout.size() - size, Ordering::Relaxed);
            }
        }
        q
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// One measuring test at a time (the counts are the whole program's).
static SERIAL: Mutex<()> = Mutex::new(());

fn serial() -> std::sync::MutexGuard<'static, ()> {
    SERIAL.lock().unwrap_or_else(|e| e.into_inner())
}

/// The most bytes allocated at once while `f` runs, above what was allocated before.
fn peak_during<T>(f: impl FnOnce() -> T) -> (T, usize) {
    let base = LIVE.load(Ordering::Relaxed);
    PEAK.store(base, Ordering::Relaxed);
    let out = f();
    (out, PEAK.load(Ordering::Relaxed).saturating_sub(base))
}

const MIB: usize = 1 << 20;

/// A deflated archive holding a model description and `zeros` bytes of zeros.
fn inflating_zip(zeros: usize) -> Vec<u8> {
    let mut zip = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    let options = zip::write::SimpleFileOptions::default()
        .compression_method(zip::CompressionMethod::Deflated);
    zip.start_file("modelDescription.xml", options).unwrap();
    zip.write_all(DESCRIPTION.as_bytes()).unwrap();
    zip.start_file("resources/zeros.bin", options).unwrap();
    let chunk = vec![0u8; MIB];
    for _ in 0..zeros / MIB {
        zip.write_all(&chunk).unwrap();
    }
    zip.finish().unwrap().into_inner()
}

/// A small FMU (a description, and `padding` bytes that make it unique).
fn small_zip(padding: &[u8]) -> Vec<u8> {
    stored_zip64(
        &[
            ("modelDescription.xml", DESCRIPTION.as_bytes()),
            ("resources/padding.bin", padding),
        ],
        Lies::default(),
    )
}

/// Entries of `root` whose names start with a dot (staging folders).
fn staging_left(root: &Path) -> Vec<String> {
    std::fs::read_dir(root).map_or_else(
        |_| Vec::new(),
        |d| {
            d.filter_map(|e| e.ok()?.file_name().into_string().ok())
                .filter(|n| n.starts_with('.'))
                .collect()
        },
    )
}

fn refused(result: Result<std::path::PathBuf, FmuError>) -> String {
    match result {
        Ok(dir) => panic!("unpacked into {}", dir.display()),
        Err(e) => e.to_string(),
    }
}

#[test]
fn an_archive_lying_about_a_size_is_refused_without_believing_it() {
    let _serial = serial();
    let root = tempfile::tempdir().unwrap();
    let lying = stored_zip64(
        &[("modelDescription.xml", DESCRIPTION.as_bytes())],
        Lies {
            first_size: Some(1 << 40),
            entries: None,
        },
    );
    assert!(lying.len() < 4096);
    let (result, peak) =
        peak_during(|| archive::unpack(&lying, "lying", root.path(), &Limits::default()));
    let message = refused(result);
    assert!(
        message.contains("header says 1099511627776 bytes"),
        "{message}"
    );
    assert!(peak < 4 * MIB, "{peak} bytes allocated at once");
    assert_eq!(staging_left(root.path()), Vec::<String>::new());
    assert!(!root.path().join("lying").exists());
}

#[test]
fn an_archive_claiming_too_many_entries_is_refused_before_they_are_read() {
    let _serial = serial();
    let root = tempfile::tempdir().unwrap();
    let claiming = stored_zip64(
        &[("modelDescription.xml", DESCRIPTION.as_bytes())],
        Lies {
            first_size: None,
            entries: Some(1 << 40),
        },
    );
    let (result, peak) =
        peak_during(|| archive::unpack(&claiming, "claiming", root.path(), &Limits::default()));
    let message = refused(result);
    assert!(
        message.contains("claims 1099511627776 entries; the limit is 10000"),
        "{message}"
    );
    assert!(peak < 4 * MIB, "{peak} bytes allocated at once");
    // And a true count past the limit.
    let many: Vec<(String, Vec<u8>)> = (0..12).map(|i| (format!("f{i}"), vec![])).collect();
    let entries: Vec<(&str, &[u8])> = many
        .iter()
        .map(|(n, d)| (n.as_str(), d.as_slice()))
        .collect();
    let limits = Limits {
        entries: 10,
        ..Limits::default()
    };
    let message = refused(archive::unpack(
        &stored_zip64(&entries, Lies::default()),
        "many",
        root.path(),
        &limits,
    ));
    assert!(message.contains("12 entries; the limit is 10"), "{message}");
    assert_eq!(staging_left(root.path()), Vec::<String>::new());
}

#[test]
fn an_inflating_archive_is_stopped_at_the_limit_while_inflating() {
    let _serial = serial();
    let bomb = inflating_zip(32 * MIB);
    assert!(bomb.len() < 100_000, "{} bytes", bomb.len());
    let root = tempfile::tempdir().unwrap();
    // The total, as a worker's cache of 5 MiB bounds it.
    let limits = Limits::default().within_cache(5 * MIB as u64);
    let (result, peak) = peak_during(|| archive::unpack(&bomb, "bomb", root.path(), &limits));
    let message = refused(result);
    assert!(
        message.contains("inflates to more than 5 MiB") && message.contains("--fmu-cache-mib"),
        "{message}"
    );
    assert!(peak < 4 * MIB, "{peak} bytes allocated at once");
    assert_eq!(staging_left(root.path()), Vec::<String>::new());
    assert!(!root.path().join("bomb").exists());
    // One file past its own limit.
    let limits = Limits {
        entry_bytes: 2 * MIB as u64,
        ..Limits::default()
    };
    let message = refused(archive::unpack(&bomb, "bomb", root.path(), &limits));
    assert!(
        message.contains("resources/zeros.bin inflates to more than 2 MiB"),
        "{message}"
    );
    // The archive itself.
    let limits = Limits {
        archive_bytes: 1000,
        ..Limits::default()
    };
    let message = refused(archive::unpack(&bomb, "bomb", root.path(), &limits));
    assert!(message.contains("more than 1000 bytes"), "{message}");
    assert_eq!(staging_left(root.path()), Vec::<String>::new());
}

fn runtime() -> tokio::runtime::Runtime {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap()
}

async fn start_worker(
    cache: &Path,
    mib: u64,
) -> (
    calib_worker::service::RunningWorker,
    SimulatorClient<tonic::transport::Channel>,
) {
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let mut config = WorkerConfig::new(listener.local_addr().unwrap());
    config.slots = 1;
    config.fmu_cache = Some((cache.to_path_buf(), mib << 20));
    let worker = serve_worker(listener, config).unwrap();
    let client = SimulatorClient::connect(format!("http://{}", worker.address()))
        .await
        .unwrap()
        .max_encoding_message_size(64 << 20);
    (worker, client)
}

fn upload(fmu: Vec<u8>) -> proto::UploadFmuRequest {
    proto::UploadFmuRequest {
        protocol_version: calib_proto::PROTOCOL_VERSION,
        fmu,
    }
}

#[test]
fn a_worker_refuses_lying_and_inflating_fmus_and_keeps_serving() {
    let _serial = serial();
    let dir = tempfile::tempdir().unwrap();
    let cache = dir.path().join("cache");
    runtime().block_on(async {
        let (worker, mut client) = start_worker(&cache, 5).await;
        let lying = stored_zip64(
            &[("modelDescription.xml", DESCRIPTION.as_bytes())],
            Lies {
                first_size: Some(1 << 40),
                entries: None,
            },
        );
        let status = client.upload_fmu(upload(lying)).await.unwrap_err();
        assert_eq!(status.code(), tonic::Code::InvalidArgument, "{status:?}");
        assert!(
            status.message().starts_with("fmu: ")
                && status.message().contains("header says 1099511627776 bytes"),
            "{}",
            status.message()
        );
        let status = client
            .upload_fmu(upload(inflating_zip(32 * MIB)))
            .await
            .unwrap_err();
        assert_eq!(status.code(), tonic::Code::InvalidArgument, "{status:?}");
        assert!(
            status.message().contains("inflates to more than 5 MiB")
                && status.message().contains("--fmu-cache-mib"),
            "{}",
            status.message()
        );
        assert_eq!(staging_left(&cache.join("unpacked")), Vec::<String>::new());
        assert_eq!(staging_left(&cache), Vec::<String>::new());
        // Still serving: a good FMU is taken, and a hosted model simulates.
        let answer = client
            .upload_fmu(upload(small_zip(b"good")))
            .await
            .unwrap()
            .into_inner();
        assert!(
            answer.models[0].starts_with("Small.cs@"),
            "{:?}",
            answer.models
        );
        let simulated = client
            .simulate(proto::SimulateRequest {
                protocol_version: calib_proto::PROTOCOL_VERSION,
                model: "furuta".into(),
                parameters: Vec::new(),
                times: vec![0.0, 0.1],
                outputs: vec!["armJoint.phi".into()],
                solver: None,
                fmu_hash: Vec::new(),
                inputs: vec![],
                effects: vec![],
            })
            .await
            .unwrap()
            .into_inner();
        assert!(simulated.failure.is_none());
        worker.shutdown().await;
    });
}

#[test]
fn uploaded_archives_are_not_kept_in_memory() {
    let _serial = serial();
    let dir = tempfile::tempdir().unwrap();
    let cache = dir.path().join("cache");
    const UPLOADS: usize = 12;
    const SIZE: usize = 3 * MIB;
    let grown = runtime().block_on(async {
        let (worker, mut client) = start_worker(&cache, 1024).await;
        let fmu = |i: usize| small_zip(&vec![i as u8; SIZE]);
        // Buffers of the connection, warmed up.
        client.upload_fmu(upload(fmu(0))).await.unwrap();
        let before = LIVE.load(Ordering::Relaxed);
        for i in 1..=UPLOADS {
            client.upload_fmu(upload(fmu(i))).await.unwrap();
        }
        let grown = LIVE.load(Ordering::Relaxed).saturating_sub(before);
        worker.shutdown().await;
        grown
    });
    assert!(
        grown < UPLOADS * SIZE / 3,
        "{grown} bytes more held after {UPLOADS} uploads of {SIZE} bytes"
    );
}

/// A small valid FMU archive, deflated, to mutate.
fn valid_zip() -> Vec<u8> {
    let mut zip = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    let options = zip::write::SimpleFileOptions::default()
        .compression_method(zip::CompressionMethod::Deflated);
    zip.start_file("modelDescription.xml", options).unwrap();
    zip.write_all(DESCRIPTION.as_bytes()).unwrap();
    zip.start_file("binaries/linux64/Small.so", options)
        .unwrap();
    zip.write_all(&[7u8; 4096]).unwrap();
    zip.finish().unwrap().into_inner()
}

/// Arbitrary bytes, or a valid archive (deflated or stored with zip64 fields) with bytes
/// flipped, set and cut.
fn archives() -> impl Strategy<Value = Vec<u8>> {
    let mutated = |base: Vec<u8>| {
        let len = base.len();
        (
            proptest::collection::vec((0..len, any::<u8>()), 0..8),
            0..=len,
        )
            .prop_map(move |(flips, keep)| {
                let mut bytes = base.clone();
                for (at, byte) in flips {
                    bytes[at] ^= byte;
                }
                bytes.truncate(keep.max(len / 2));
                bytes
            })
    };
    prop_oneof![
        proptest::collection::vec(any::<u8>(), 0..2048),
        mutated(valid_zip()),
        mutated(small_zip(b"0123456789")),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(192))]

    #[test]
    fn any_archive_is_unpacked_or_refused_within_bounded_memory(bytes in archives()) {
        let _serial = serial();
        let root = tempfile::tempdir().unwrap();
        let limits = Limits {
            archive_bytes: 1 << 20,
            entries: 64,
            entry_bytes: 1 << 20,
            inflated_bytes: 4 << 20,
            ..Limits::default()
        };
        let (result, peak) = peak_during(|| archive::unpack(&bytes, "fmu", root.path(), &limits));
        prop_assert!(peak < 16 * MIB, "{} bytes allocated at once", peak);
        prop_assert_eq!(staging_left(root.path()), Vec::<String>::new());
        if let Ok(dir) = result {
            let (_, peak) = peak_during(|| {
                archive::read_description(&dir).and_then(|xml| Description::parse(&xml))
            });
            prop_assert!(peak < 16 * MIB, "{} bytes allocated at once", peak);
        }
    }

    #[test]
    fn any_model_description_is_parsed_or_refused(
        flips in proptest::collection::vec((0..DESCRIPTION.len(), any::<u8>()), 0..6),
        keep in 0..=DESCRIPTION.len(),
    ) {
        let mut bytes = DESCRIPTION.as_bytes().to_vec();
        for (at, byte) in flips {
            bytes[at] ^= byte;
        }
        bytes.truncate(keep);
        let _ = Description::parse(&String::from_utf8_lossy(&bytes));
    }
}
