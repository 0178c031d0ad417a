//! Hostile motion files against a real `choreo serve` process: the 1 KB BVH that once aborted
//! the server (as a rig, a seed motion and a key pose), non-finite numbers, and a 9 MB glTF of
//! millions of empty nodes, whose cost in the server's memory is measured from /proc.
use crate::helpers::{expect_problem, short_song};
use crate::hostile::Serve;
use crate::motion_files::{claiming_frames, rig_fixture};
use reqwest::multipart::{Form, Part};
use reqwest::StatusCode;
use serde_json::{json, Value};
use std::time::{Duration, Instant};

fn client() -> reqwest::Client {
    reqwest::Client::builder()
        .timeout(Duration::from_secs(120))
        .build()
        .expect("client")
}

async fn upload_rig(
    client: &reqwest::Client,
    url: &str,
    name: &str,
    bytes: Vec<u8>,
) -> reqwest::Response {
    let form = Form::new().part("file", Part::bytes(bytes).file_name(name.to_string()));
    client
        .post(format!("{url}/v1/rigs"))
        .multipart(form)
        .send()
        .await
        .expect("POST /v1/rigs")
}

async fn healthy(client: &reqwest::Client, serve: &mut Serve) {
    assert!(serve.alive(), "the server process died");
    let health = client
        .get(format!("{}/healthz", serve.url))
        .send()
        .await
        .expect("the server answers");
    assert_eq!(health.status(), StatusCode::OK);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_one_kilobyte_bvh_is_refused_everywhere_and_the_server_lives() {
    let mut serve = Serve::start_with(&[], Some(&crate::common_models::models_dir()));
    let client = client();
    healthy(&client, &mut serve).await;
    let form = Form::new().part(
        "file",
        Part::bytes(std::fs::read(short_song()).expect("song")).file_name("song.ogg"),
    );
    let song: Value = client
        .post(format!("{}/v1/songs", serve.url))
        .multipart(form)
        .send()
        .await
        .expect("upload")
        .json()
        .await
        .expect("song");
    let song_id = song["id"].as_str().expect("song id").to_string();

    for frames in ["10000000000", "1000000000000000000"] {
        let bvh = claiming_frames(frames);
        let started = Instant::now();
        let rig = upload_rig(&client, &serve.url, "rig.bvh", bvh.clone().into_bytes()).await;
        expect_problem(rig, StatusCode::UNPROCESSABLE_ENTITY, "rig-bvh").await;
        healthy(&client, &mut serve).await;
        let as_seed =
            json!({"song_id": song_id, "model": "dance-revolution", "seed_motion": {"bvh": bvh}});
        let as_key = json!({"song_id": song_id, "model": "keypose-transformer",
            "key_poses": [{"time_s": 1.0, "bvh": {"text": bvh, "frame": 0}}]});
        for body in [as_seed, as_key] {
            let response = client
                .post(format!("{}/v1/jobs", serve.url))
                .json(&body)
                .send()
                .await
                .expect("the server answers the job");
            let problem =
                expect_problem(response, StatusCode::UNPROCESSABLE_ENTITY, "invalid-field").await;
            assert!(
                problem["detail"]
                    .as_str()
                    .unwrap_or("")
                    .contains(&format!("{frames} frames")),
                "{problem}"
            );
            healthy(&client, &mut serve).await;
        }
        eprintln!(
            "{} bytes claiming {frames} frames: 422 as a rig, a seed motion and a key pose in {:?}; the server lives",
            bvh.len(),
            started.elapsed()
        );
    }

    // A number that is not finite: 422 motion-not-finite, as a rig and as a seed motion.
    let nan = rig_fixture().replacen("OFFSET", "OFFSET NaN 10 0 #", 2);
    let rig = upload_rig(&client, &serve.url, "nan.bvh", nan.into_bytes()).await;
    let problem = expect_problem(rig, StatusCode::UNPROCESSABLE_ENTITY, "motion-not-finite").await;
    assert_eq!(problem["field"], "file", "{problem}");
    let seed = "HIERARCHY\nROOT body_centre\n{\nOFFSET 0 inf 0\nCHANNELS 3 Zrotation Yrotation Xrotation\n}\nMOTION\nFrames: 1\nFrame Time: 0.04\n0 0 0\n";
    let response = client
        .post(format!("{}/v1/jobs", serve.url))
        .json(
            &json!({"song_id": song_id, "model": "dance-revolution", "seed_motion": {"bvh": seed}}),
        )
        .send()
        .await
        .expect("answer");
    let problem = expect_problem(
        response,
        StatusCode::UNPROCESSABLE_ENTITY,
        "motion-not-finite",
    )
    .await;
    assert_eq!(problem["field"], "seed_motion", "{problem}");
    healthy(&client, &mut serve).await;
}

/// A glTF JSON of `nodes` empty nodes and a skin.
fn empty_nodes(nodes: usize) -> Vec<u8> {
    format!(
        "{{\"asset\": {{\"version\": \"2.0\"}}, \"skins\": [{{\"joints\": [0]}}], \"nodes\": [{}{{}}]}}",
        "{},".repeat(nodes - 1)
    )
    .into_bytes()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_nine_megabyte_gltf_rig_costs_a_few_times_its_size() {
    let mut serve = Serve::start(&[]);
    let client = client();
    healthy(&client, &mut serve).await;
    // Warm the rig path up first, so what is measured is the file's own cost.
    let warm = upload_rig(&client, &serve.url, "rig.bvh", rig_fixture().into_bytes()).await;
    assert_eq!(warm.status(), StatusCode::CREATED);
    let gltf = empty_nodes(3_000_000);
    let size_kb = gltf.len() as u64 / 1024;
    let idle = serve.status_kb("VmHWM");
    let started = Instant::now();
    let refused = upload_rig(&client, &serve.url, "nodes.gltf", gltf.clone()).await;
    let problem = expect_problem(refused, StatusCode::UNPROCESSABLE_ENTITY, "rig-gltf").await;
    assert!(
        problem["detail"]
            .as_str()
            .unwrap_or("")
            .contains("65536 nodes"),
        "{problem}"
    );
    let one = serve.status_kb("VmHWM").saturating_sub(idle);
    eprintln!(
        "glTF of 3,000,000 empty nodes ({size_kb} KB): 422 in {:?}, peak RSS +{one} KB ({:.2}x its size)",
        started.elapsed(),
        one as f64 / size_kb as f64
    );
    assert!(one <= 4 * size_kb, "+{one} KB for a {size_kb} KB file");
    // Two at once share the decode budget.
    let before = serve.status_kb("VmHWM");
    let (a, b) = tokio::join!(
        upload_rig(&client, &serve.url, "a.gltf", gltf.clone()),
        upload_rig(&client, &serve.url, "b.gltf", gltf),
    );
    assert_eq!(a.status(), StatusCode::UNPROCESSABLE_ENTITY);
    assert_eq!(b.status(), StatusCode::UNPROCESSABLE_ENTITY);
    let two = serve.status_kb("VmHWM").saturating_sub(idle);
    eprintln!(
        "two at once: peak RSS +{two} KB above idle (+{} KB past the single one's peak)",
        serve.status_kb("VmHWM").saturating_sub(before)
    );
    assert!(two <= 8 * size_kb, "+{two} KB for two {size_kb} KB files");
    healthy(&client, &mut serve).await;
}
