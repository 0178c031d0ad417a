//! The readers of user motion under hostile input: BVH (rigs, seed motions, key poses), glTF and
//! glb rigs, and key poses and seed motions as JSON. A bounded fuzz run (a seeded mutation corpus,
//! [`FUZZ_FOR`]) finds no panic, no abort and no allocation past [`MAX_ALLOCATION`] from inputs of
//! at most 1 MB, and the files that once took the server down are refused in memory that follows
//! their bytes.
//!
//! Memory is measured by a counting allocator, per thread (each reader runs on the test's own
//! thread): the largest single allocation, and the peak of what the reader held at once.
//! cargo-fuzz needs a nightly toolchain and runs outside `make test`; this corpus runs inside it.
use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::collections::BTreeMap;
use std::panic::AssertUnwindSafe;
use std::time::{Duration, Instant};

use choreo::motion::bvh::Bvh;
use choreo::motion::dataset::{Dataset, DEFAULT_ROOT};
use choreo::motion::export;
use choreo::motion::input::{self, KeyPoseInput, SeedMotionInput};
use choreo::motion::retarget::uploaded;
use choreo::motion::{Motion, MOTION_FPS};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use std::path::Path;

#[path = "common/motion_files.rs"]
mod motion_files;
use motion_files::{claiming_frames, rig_fixture};

/// The most any reader may ask for at once.
const MAX_ALLOCATION: usize = 64 * 1024 * 1024;
/// How long the mutation run lasts (it also stops after [`FUZZ_INPUTS`]).
const FUZZ_FOR: Duration = Duration::from_secs(20);
const FUZZ_INPUTS: usize = 50_000;
/// Largest input the run tries.
const MAX_INPUT: usize = 1024 * 1024;

struct Counting;

thread_local! {
    static LIVE: Cell<usize> = const { Cell::new(0) };
    static PEAK: Cell<usize> = const { Cell::new(0) };
    static LARGEST: Cell<usize> = const { Cell::new(0) };
}

fn grew(by: usize, size: usize) {
    let _ = LIVE.try_with(|live| {
        let now = live.get().saturating_add(by);
        live.set(now);
        let _ = PEAK.try_with(|peak| peak.set(peak.get().max(now)));
    });
    let _ = LARGEST.try_with(|largest| largest.set(largest.get().max(size)));
}

fn shrank(by: usize) {
    let _ = LIVE.try_with(|live| live.set(live.get().saturating_sub(by)));
}

// SAFETY: every call is passed on to the system allocator unchanged; the counters are
// thread-local cells with const initialisers, which neither allocate nor need a destructor.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        grew(layout.size(), layout.size());
        unsafe { System.alloc(layout) }
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        grew(layout.size(), layout.size());
        unsafe { System.alloc_zeroed(layout) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        shrank(layout.size());
        unsafe { System.dealloc(ptr, layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        if new_size >= layout.size() {
            grew(new_size - layout.size(), new_size);
        } else {
            shrank(layout.size() - new_size);
        }
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static COUNTING: Counting = Counting;

/// What one reading cost: the peak held at once and the largest single allocation, bytes.
#[derive(Clone, Copy, Debug, Default)]
struct Cost {
    peak: usize,
    largest: usize,
}

/// Runs `read`, measuring what it allocates on this thread.
fn measured<T>(read: impl FnOnce() -> T) -> (T, Cost) {
    LIVE.with(|c| c.set(0));
    PEAK.with(|c| c.set(0));
    LARGEST.with(|c| c.set(0));
    let out = read();
    let cost = Cost {
        peak: PEAK.with(Cell::get),
        largest: LARGEST.with(Cell::get),
    };
    (out, cost)
}

/// The first `frames` frames of a real training dance; none when the dataset is missing
/// (then CI fails loudly, and elsewhere the run goes on without the motion seeds).
fn real_dance(frames: usize) -> Option<Motion> {
    match Dataset::open(Path::new(DEFAULT_ROOT)) {
        Ok(ds) => {
            let id = ds.train_ids().first().expect("a training dance").clone();
            let dance = ds.load(&id).expect("load a training dance");
            let positions = dance
                .motion
                .positions
                .slice(ndarray::s![..frames, .., ..])
                .to_owned();
            Some(Motion {
                fps: dance.motion.fps,
                positions,
            })
        }
        Err(e) => {
            assert!(
                std::env::var("CI").as_deref() != Ok("true"),
                "CI=true but the dataset is missing: {e}"
            );
            eprintln!("SKIPPED the motion seeds: {e}");
            None
        }
    }
}

/// A glTF JSON rig made from a BVH hierarchy: one node per joint, translations its offsets.
fn gltf_of(bvh: &str) -> String {
    let b = Bvh::parse_rest_pose(bvh).expect("fixture hierarchy");
    let nodes: Vec<serde_json::Value> = (0..b.names.len())
        .map(|j| {
            let children: Vec<usize> = (0..b.names.len())
                .filter(|&c| b.parents[c] == Some(j))
                .collect();
            let o = b.offsets[j];
            serde_json::json!({"name": b.names[j], "translation": [o.x, o.y, o.z], "children": children})
        })
        .collect();
    let joints: Vec<usize> = (0..b.names.len()).collect();
    serde_json::json!({"asset": {"version": "2.0"}, "nodes": nodes, "skins": [{"joints": joints}]})
        .to_string()
}

/// The inputs the mutations start from: every reader's valid input.
fn seeds() -> Vec<Vec<u8>> {
    let fixture = rig_fixture();
    let mut seeds = vec![fixture.clone().into_bytes(), gltf_of(&fixture).into_bytes()];
    if let Some(dance) = real_dance(30) {
        let rig = export::prepare(&dance).expect("prepare");
        seeds.push(export::bvh_string(&rig).expect("bvh").into_bytes());
        seeds.push(export::glb_bytes(&rig).expect("glb"));
        seeds.push(export::json_string(&rig).expect("json").into_bytes());
        let frames: Vec<Vec<[f64; 3]>> = dance
            .positions
            .outer_iter()
            .take(8)
            .map(|f| {
                f.outer_iter()
                    .map(|p| [f64::from(p[0]), f64::from(p[1]), f64::from(p[2])])
                    .collect()
            })
            .collect();
        let seed =
            serde_json::json!({"fps": dance.fps, "joint_set": "dataset", "positions": frames});
        seeds.push(seed.to_string().into_bytes());
    }
    seeds
}

const NASTY_NUMBERS: [&str; 12] = [
    "10000000000",
    "1000000000000000000",
    "18446744073709551615",
    "1e18",
    "NaN",
    "inf",
    "-inf",
    "-1",
    "0",
    "1e308",
    "1e39",
    "4294967295",
];

/// One mutation of `input`.
fn mutate(input: &[u8], rng: &mut StdRng) -> Vec<u8> {
    let mut out = input.to_vec();
    match rng.gen_range(0..8) {
        0 => {
            for _ in 0..rng.gen_range(1..8) {
                if !out.is_empty() {
                    let i = rng.gen_range(0..out.len());
                    out[i] = rng.gen();
                }
            }
        }
        1 | 2 => {
            // A number replaced by a nasty one.
            let text = String::from_utf8_lossy(&out).into_owned();
            let starts: Vec<usize> = text
                .char_indices()
                .filter(|&(i, c)| {
                    c.is_ascii_digit()
                        && (i == 0 || !text.as_bytes()[i - 1].is_ascii_alphanumeric())
                })
                .map(|(i, _)| i)
                .collect();
            if let Some(&i) = starts.get(rng.gen_range(0..starts.len().max(1))) {
                let end = text[i..]
                    .find(|c: char| !(c.is_ascii_digit() || c == '.' || c == 'e' || c == '-'))
                    .map_or(text.len(), |n| i + n);
                let nasty = NASTY_NUMBERS[rng.gen_range(0..NASTY_NUMBERS.len())];
                out = format!("{}{nasty}{}", &text[..i], &text[end..]).into_bytes();
            }
        }
        3 => {
            // Every line holding a keyword removed (CHANNELS: the 1 KB file's way).
            let keyword =
                ["CHANNELS", "End Site", "OFFSET", "}", "MOTION", "joints"][rng.gen_range(0..6)];
            let text = String::from_utf8_lossy(&out).into_owned();
            out = text
                .lines()
                .filter(|l| !l.contains(keyword))
                .collect::<Vec<_>>()
                .join("\n")
                .into_bytes();
        }
        4 => {
            // A range repeated.
            if !out.is_empty() {
                let a = rng.gen_range(0..out.len());
                let b = (a + rng.gen_range(1..4096)).min(out.len());
                let piece = out[a..b].to_vec();
                for _ in 0..rng.gen_range(1..64) {
                    if out.len() + piece.len() > MAX_INPUT {
                        break;
                    }
                    out.splice(b..b, piece.iter().copied());
                }
            }
        }
        5 => {
            let at = rng.gen_range(0..=out.len());
            out.truncate(at);
        }
        6 => {
            // A glb's declared lengths.
            if out.len() >= 20 {
                let at = [8, 12][rng.gen_range(0..2)];
                let v: u32 = [u32::MAX, 0, 1 << 31, rng.gen()][rng.gen_range(0..4)];
                out[at..at + 4].copy_from_slice(&v.to_le_bytes());
            }
        }
        _ => {
            let text = String::from_utf8_lossy(&out).into_owned();
            let frames = NASTY_NUMBERS[rng.gen_range(0..NASTY_NUMBERS.len())];
            out = text
                .lines()
                .map(|l| {
                    if l.starts_with("Frames:") {
                        format!("Frames: {frames}")
                    } else {
                        l.to_string()
                    }
                })
                .collect::<Vec<_>>()
                .join("\n")
                .into_bytes();
        }
    }
    out.truncate(MAX_INPUT);
    out
}

/// Every reader of user motion on `bytes`; what each said is dropped, only its cost is kept.
fn read_all(bytes: &[u8]) -> Cost {
    let mut worst = Cost::default();
    let mut keep = |cost: Cost| {
        worst.peak = worst.peak.max(cost.peak);
        worst.largest = worst.largest.max(cost.largest);
    };
    keep(measured(|| uploaded::read(bytes, &BTreeMap::new()).is_ok()).1);
    if let Ok(text) = std::str::from_utf8(bytes) {
        keep(measured(|| Bvh::parse(text).is_ok()).1);
        let seed = SeedMotionInput {
            fps: None,
            joint_set: None,
            positions: None,
            bvh: Some(text.to_string()),
        };
        keep(measured(|| input::seed_motion(&seed).is_ok()).1);
        let key = KeyPoseInput {
            time_s: 0.4,
            joint_set: None,
            joints: None,
            bvh: Some(input::BvhFrame {
                text: text.to_string(),
                frame: 3,
            }),
        };
        keep(measured(|| input::key_poses(&[key], 250, MOTION_FPS).is_ok()).1);
    }
    // As JSON: a seed motion (positions) or a key pose list, as the API parses them.
    keep(
        measured(|| {
            serde_json::from_slice::<SeedMotionInput>(bytes)
                .map(|s| input::seed_motion(&s).is_ok())
                .is_ok()
        })
        .1,
    );
    keep(
        measured(|| {
            serde_json::from_slice::<Vec<KeyPoseInput>>(bytes)
                .map(|k| input::key_poses(&k, 250, MOTION_FPS).is_ok())
                .is_ok()
        })
        .1,
    );
    worst
}

#[test]
fn a_bounded_fuzz_run_finds_no_panic_and_no_large_allocation() {
    let mut corpus = seeds();
    let seeds = corpus.len();
    let mut rng = StdRng::seed_from_u64(68);
    let started = Instant::now();
    let (mut tried, mut worst, mut worst_ratio) = (0usize, Cost::default(), 0.0f64);
    // Quiet: the panics caught are reported by the assertion below with their input.
    let hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(|_| {}));
    while started.elapsed() < FUZZ_FOR && tried < FUZZ_INPUTS {
        let parent = &corpus[rng.gen_range(0..corpus.len())];
        let input = mutate(parent, &mut rng);
        let outcome = std::panic::catch_unwind(AssertUnwindSafe(|| read_all(&input)));
        let cost = match outcome {
            Ok(cost) => cost,
            Err(_) => {
                std::panic::set_hook(hook);
                let path = std::env::temp_dir().join("choreo-reader-panic.bin");
                let _ = std::fs::write(&path, &input);
                panic!(
                    "a reader panicked on input {tried} (kept at {})",
                    path.display()
                );
            }
        };
        assert!(
            cost.largest <= MAX_ALLOCATION,
            "input {tried} ({} bytes) asked for {} bytes at once",
            input.len(),
            cost.largest
        );
        worst.peak = worst.peak.max(cost.peak);
        worst.largest = worst.largest.max(cost.largest);
        worst_ratio = worst_ratio.max(cost.peak as f64 / input.len().max(1024) as f64);
        // Keep some mutants as parents, so mutations stack.
        if corpus.len() < 400 && rng.gen_bool(0.05) {
            corpus.push(input);
        }
        tried += 1;
    }
    std::panic::set_hook(hook);
    eprintln!(
        "fuzz: {tried} inputs from {seeds} seeds in {:.1} s; largest allocation {} KB, peak held {} KB, \
         peak per input byte (inputs ≥ 1 KB) {worst_ratio:.1}; limit {} MB",
        started.elapsed().as_secs_f64(),
        worst.largest / 1024,
        worst.peak / 1024,
        MAX_ALLOCATION >> 20
    );
    assert!(worst.peak <= MAX_ALLOCATION, "peak {} bytes", worst.peak);
    assert!(tried >= 1000, "only {tried} inputs in {FUZZ_FOR:?}");
}

/// The 1 KB BVH that once aborted the server (every CHANNELS clause removed, ten billion frames
/// claimed), as a rig, a seed motion and a key pose, and a 1e18-frame one that panicked.
#[test]
fn the_one_kilobyte_bvh_is_refused_at_once() {
    for frames in ["10000000000", "1000000000000000000"] {
        let text = format!("{}0 0 0\n", claiming_frames(frames));
        let (cost, took) = {
            let started = Instant::now();
            (read_all(text.as_bytes()), started.elapsed())
        };
        eprintln!(
            "{} bytes claiming {frames} frames: refused by every reader in {took:?}, peak {} KB",
            text.len(),
            cost.peak / 1024
        );
        assert!(cost.peak < 64 * text.len().max(16 * 1024), "{cost:?}");
        assert!(Bvh::parse(&text).is_err());
        assert!(uploaded::read(text.as_bytes(), &BTreeMap::new()).is_err());
    }
    let nan = rig_fixture().replacen("OFFSET", "OFFSET NaN 10 0 #", 2);
    let err = uploaded::read(nan.as_bytes(), &BTreeMap::new()).expect_err("refused");
    assert_eq!(err.code(), "motion-not-finite", "{err}");
}

/// A glTF of millions of empty nodes is refused while its nodes are read: what a glTF costs
/// follows its bytes, at most 4 times them and a constant (the 9 MB one once held 75 times).
#[test]
fn a_gltf_of_millions_of_empty_nodes_costs_a_few_times_its_size() {
    const CONSTANT: usize = 2 * 1024 * 1024;
    for nodes in [3_000_000usize, 65_536, 10_000] {
        let json = format!(
            "{{\"asset\": {{\"version\": \"2.0\"}}, \"skins\": [{{\"joints\": [0]}}], \"nodes\": [{}{{}}]}}",
            "{},".repeat(nodes - 1)
        );
        let (read, cost) = measured(|| uploaded::read(json.as_bytes(), &BTreeMap::new()));
        eprintln!(
            "glTF of {nodes} empty nodes ({:.2} MB): {} holding at most {:.2} MB, {:.2}x its size",
            json.len() as f64 / 1e6,
            match &read {
                Ok(_) => "read".to_string(),
                Err(e) => format!("refused ({})", e.code()),
            },
            cost.peak as f64 / 1e6,
            cost.peak as f64 / json.len() as f64
        );
        assert!(read.is_err(), "no humanoid in empty nodes");
        assert!(
            cost.peak <= 4 * json.len() + CONSTANT,
            "{} bytes held for {} sent",
            cost.peak,
            json.len()
        );
    }
}
