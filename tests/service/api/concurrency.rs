//! Concurrent illuminant PUTs and DELETEs: all kept, and memory equal to the database.

use crate::service_support::*;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn concurrent_illuminant_changes_are_all_kept() {
    let data = tempfile::tempdir().unwrap();
    let server = l3::service::start(test_config(data.path())).await.unwrap();
    let c = client();
    // 12 PUTs of different lights at once: none may undo another
    let put = |i: u32| {
        let (c, u) = (c.clone(), url(&server, &format!("/v1/illuminants/Lamp{i}")));
        tokio::spawn(async move {
            c.put(u)
                .json(&serde_json::json!({"cct": 2500 + 300 * i}))
                .send()
                .await
                .unwrap()
                .status()
                .as_u16()
        })
    };
    let del = |i: u32| {
        let (c, u) = (c.clone(), url(&server, &format!("/v1/illuminants/Lamp{i}")));
        tokio::spawn(async move { c.delete(u).send().await.unwrap().status().as_u16() })
    };
    async fn all(h: Vec<tokio::task::JoinHandle<u16>>) -> Vec<u16> {
        let mut out = Vec::new();
        for h in h {
            out.push(h.await.unwrap());
        }
        out
    }
    let statuses = all((0..12).map(put).collect()).await;
    assert!(statuses.iter().all(|s| *s == 201), "{statuses:?}");
    for i in 0..12 {
        let v = json(
            c.get(url(&server, &format!("/v1/illuminants/lamp{i}")))
                .send()
                .await
                .unwrap(),
        )
        .await;
        assert_eq!(v["cct"], f64::from(2500 + 300 * i), "Lamp{i}: {v}");
    }
    // DELETEs racing PUTs of other names, started together: the deleted
    // stay deleted, the created stay
    let handles_d: Vec<_> = (0..6).map(del).collect();
    let handles_p: Vec<_> = (12..18).map(put).collect();
    let (d, p) = (all(handles_d).await, all(handles_p).await);
    assert!(d.iter().all(|s| *s == 204), "{d:?}");
    assert!(p.iter().all(|s| *s == 201), "{p:?}");
    let list = json(c.get(url(&server, "/v1/illuminants")).send().await.unwrap()).await;
    let text = list.to_string().to_ascii_lowercase();
    for i in 0..18 {
        let name = format!("\"lamp{i}\"");
        assert_eq!(text.contains(&name), i >= 6, "lamp{i} in {text}");
    }
    server.shutdown().await.unwrap();
}

/// 50 PUT/DELETE pairs of the same names, each pair sent at once: whatever order they land in,
/// the registry in memory (the list the running service answers with) equals the database (the
/// list a restart on the same database loads).
#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn racing_puts_and_deletes_leave_memory_equal_to_the_database() {
    let data = tempfile::tempdir().unwrap();
    let cfg = test_config(data.path());
    let server = l3::service::start(cfg.clone()).await.unwrap();
    let c = client();
    let mut handles = Vec::new();
    for i in 0..50u32 {
        let name = format!("Race{}", i % 10);
        let (cp, up) = (c.clone(), url(&server, &format!("/v1/illuminants/{name}")));
        handles.push(tokio::spawn(async move {
            let r = cp
                .put(up)
                .json(&serde_json::json!({"cct": 2500 + 50 * i}))
                .send();
            ("PUT", r.await.unwrap().status().as_u16())
        }));
        let (cd, ud) = (c.clone(), url(&server, &format!("/v1/illuminants/{name}")));
        handles.push(tokio::spawn(async move {
            (
                "DELETE",
                cd.delete(ud).send().await.unwrap().status().as_u16(),
            )
        }));
    }
    for h in handles {
        let (method, status) = h.await.unwrap();
        let ok: &[u16] = if method == "PUT" {
            &[200, 201]
        } else {
            &[204, 404]
        };
        assert!(ok.contains(&status), "{method} answered {status}");
    }
    let listed = |v: serde_json::Value| -> Vec<String> {
        let mut out: Vec<String> = v["items"]
            .as_array()
            .unwrap_or_else(|| panic!("no items: {v}"))
            .iter()
            .map(|e| e.to_string())
            .filter(|e| e.to_ascii_lowercase().contains("race"))
            .collect();
        out.sort();
        out
    };
    let in_memory =
        listed(json(c.get(url(&server, "/v1/illuminants")).send().await.unwrap()).await);
    server.shutdown().await.unwrap();
    let again = l3::service::start(cfg).await.unwrap();
    let in_database =
        listed(json(c.get(url(&again, "/v1/illuminants")).send().await.unwrap()).await);
    eprintln!(
        "{} registered after the race: {in_memory:?}",
        in_memory.len()
    );
    assert_eq!(in_memory, in_database);
    again.shutdown().await.unwrap();
}
