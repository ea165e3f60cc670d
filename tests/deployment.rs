//! docker-compose.yml and the Dockerfile agree with each other and with the binaries. No Docker
//! engine runs here, so this checks what can be checked without one.

use yaml_rust2::{Yaml, YamlLoader};

fn compose() -> Yaml {
    let text =
        std::fs::read_to_string("docker-compose.yml").expect("docker-compose.yml at the top level");
    YamlLoader::load_from_str(&text)
        .expect("docker-compose.yml is valid YAML")
        .remove(0)
}

fn command(service: &Yaml) -> Vec<String> {
    service["command"]
        .as_vec()
        .expect("every service has an exec-form command")
        .iter()
        .map(|w| w.as_str().expect("string words").to_string())
        .collect()
}

/// The value after `flag` in `words`.
fn after<'a>(words: &'a [String], flag: &str) -> &'a str {
    &words[words
        .iter()
        .position(|w| w == flag)
        .unwrap_or_else(|| panic!("{flag}"))
        + 1]
}

#[test]
fn compose_names_nats_the_origin_two_edges_viewers_and_load_tester() {
    let doc = compose();
    let services = doc["services"].as_hash().expect("services");
    let names: Vec<&str> = services.keys().filter_map(Yaml::as_str).collect();
    assert_eq!(
        names,
        ["nats", "server", "edge-a", "edge-b", "viewers", "load"]
    );
    let nats_url = "nats://nats:4222";
    let server = &doc["services"]["server"];
    assert_eq!(
        server["build"].as_str(),
        Some("."),
        "the server builds from the top-level Dockerfile"
    );
    assert_eq!(
        after(&command(server), "--nats"),
        nats_url,
        "the origin publishes to NATS"
    );
    let nats = command(&doc["services"]["nats"]);
    assert!(
        nats.contains(&"-js".to_string()),
        "NATS runs JetStream: {nats:?}"
    );
    let image = server["image"]
        .as_str()
        .expect("the server names its image");
    for edge in ["edge-a", "edge-b"] {
        let service = &doc["services"][edge];
        let words = command(service);
        assert!(words.contains(&"--edge".to_string()), "{edge}: {words:?}");
        assert_eq!(
            after(&words, "--nats"),
            nats_url,
            "{edge} follows the same NATS"
        );
        assert_eq!(service["image"].as_str(), Some(image));
        assert_eq!(
            service["depends_on"]["server"]["condition"].as_str(),
            Some("service_healthy"),
            "{edge} starts once the origin answers"
        );
    }
    for name in ["viewers", "load"] {
        let service = &doc["services"][name];
        assert_eq!(
            service["image"].as_str(),
            Some(image),
            "{name} runs the image the server builds"
        );
        for edge in ["edge-a", "edge-b"] {
            assert_eq!(
                service["depends_on"][edge]["condition"].as_str(),
                Some("service_healthy"),
                "{name} waits for {edge}"
            );
        }
        // Viewers reach the edges by their service names on the port the image listens on.
        let words = command(service);
        assert_eq!(
            after(&words, "--url"),
            "ws://edge-a:8080/ws,ws://edge-b:8080/ws"
        );
    }
    for volume in ["cache", "renders", "nats"] {
        assert!(
            !doc["volumes"][volume].is_badvalue(),
            "volume {volume} is declared"
        );
    }
    assert!(command(&doc["services"]["viewers"]).contains(&"/renders/view.png".to_string()));
}

#[test]
fn every_command_runs_a_binary_the_dockerfile_installs() {
    let dockerfile = std::fs::read_to_string("Dockerfile").expect("Dockerfile at the top level");
    assert!(
        dockerfile.contains("ENV RADCAST_ADDR=0.0.0.0:8080"),
        "the image listens where compose maps"
    );
    assert!(dockerfile.contains("EXPOSE 8080"));
    let installed: Vec<&str> = dockerfile
        .lines()
        .filter(|l| l.starts_with("COPY --from=build"))
        .flat_map(|l| l.split_whitespace())
        .filter_map(|w| w.strip_prefix("/src/target/release/"))
        .collect();
    assert_eq!(installed, ["radcast-server", "radcast-client", "radcast"]);
    let doc = compose();
    for (name, service) in doc["services"].as_hash().expect("services") {
        if name.as_str() == Some("nats") {
            continue; // NATS's own image
        }
        let words = command(service);
        assert!(
            installed.contains(&words[0].as_str()),
            "{name:?} runs {}, which the image lacks",
            words[0]
        );
        // Each binary is a package of this workspace.
        let package = if words[0] == "radcast" {
            "radcast-solver"
        } else {
            words[0].as_str()
        };
        let manifest = std::fs::read_to_string(format!(
            "crates/{}/Cargo.toml",
            package.trim_start_matches("radcast-")
        ))
        .expect("crate exists");
        assert!(
            manifest.contains(&format!("name = \"{}\"", words[0])),
            "{} is a binary of {package}",
            words[0]
        );
    }
}
