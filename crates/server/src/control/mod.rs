//! The control API as plain functions: check the token, parse the edit's JSON, queue the
//! edit. The HTTP route calls [`apply`] on the origin; on an edge the same request travels
//! over NATS and the origin's responder ([`crate::fanout::origin`]) calls [`apply`], so a
//! request gets the same answer wherever it is sent.

pub mod edits;

use crate::Shared;
use axum::http::{StatusCode, header};
use axum::response::{IntoResponse, Response};

/// Which property of an object an edit sets.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Field {
    /// `PUT /api/objects/{name}/emission` with `{"emission": [r, g, b]}` (W/m^2).
    Emission,
    /// `PUT /api/objects/{name}/transform` with `{"translate": [x, y, z]}` and/or
    /// `{"rotate": {"axis": [x, y, z], "degrees": d}}`, `"pivot": [x, y, z]` optional (scene
    /// units; [`solver::Motion`]).
    Move,
}

impl Field {
    /// The field's name where a request travels between servers (an edge's forwarding).
    pub fn key(self) -> &'static str {
        match self {
            Field::Emission => "emission",
            Field::Move => "translate",
        }
    }

    /// The field whose name is `key`.
    pub fn from_key(key: &str) -> Option<Field> {
        [Field::Emission, Field::Move]
            .into_iter()
            .find(|f| f.key() == key)
    }
}

/// A checked edit, ready to queue.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Edit {
    /// A new emission, W/m^2.
    Emission([f64; 3]),
    /// A rigid move.
    Move(solver::Motion),
}

/// A control request's answer: its status and JSON body.
#[derive(Clone, Debug, PartialEq)]
pub struct Reply {
    /// The HTTP status.
    pub status: StatusCode,
    /// `{"object": …, "status": "queued", FIELD: […]}` or `{"error": reason}`.
    pub body: serde_json::Value,
}

impl Reply {
    /// A refusal with its reason.
    pub fn refusal(status: StatusCode, reason: impl Into<String>) -> Reply {
        Reply {
            status,
            body: serde_json::json!({ "error": reason.into() }),
        }
    }
}

impl IntoResponse for Reply {
    fn into_response(self) -> Response {
        let unauthorized = self.status == StatusCode::UNAUTHORIZED;
        let mut response = (self.status, axum::Json(self.body)).into_response();
        if unauthorized {
            response.headers_mut().insert(
                header::WWW_AUTHENTICATE,
                header::HeaderValue::from_static("Bearer"),
            );
        }
        response
    }
}

/// Whether `authorization` (an `Authorization` header's value) is `Bearer <token>`, compared
/// in constant time. An empty token authorizes nothing.
pub fn authorized(authorization: Option<&str>, token: &str) -> bool {
    let Some(given) = authorization.and_then(|v| v.strip_prefix("Bearer ")) else {
        return false;
    };
    !token.is_empty()
        && given.len() == token.len()
        && given
            .bytes()
            .zip(token.bytes())
            .fold(0u8, |acc, (a, b)| acc | (a ^ b))
            == 0
}

/// Checks an edit: the object exists and the body is the field's JSON (see [`Field`]) with
/// values the solver's rule for it accepts. Returns the edit or the refusal.
pub fn parse_edit(
    objects: &[String],
    name: &str,
    body: &[u8],
    field: Field,
) -> Result<Edit, Reply> {
    if !objects.iter().any(|o| o == name) {
        return Err(Reply::refusal(
            StatusCode::NOT_FOUND,
            format!("no object named '{name}'"),
        ));
    }
    let bad = |reason: String| Reply::refusal(StatusCode::BAD_REQUEST, reason);
    match field {
        Field::Emission => {
            let shape = || "body must be JSON like {\"emission\": [a, b, c]}".to_string();
            let value: serde_json::Value =
                serde_json::from_slice(body).map_err(|e| bad(format!("{}: {e}", shape())))?;
            let triple: [f64; 3] = value
                .as_object()
                .filter(|o| o.len() == 1)
                .and_then(|o| o.get("emission"))
                .and_then(|v| serde_json::from_value(v.clone()).ok())
                .ok_or_else(|| bad(shape()))?;
            solver::check_emission(triple).map_err(|rule| bad(format!("emission {rule}")))?;
            Ok(Edit::Emission(triple))
        }
        Field::Move => {
            let shape = "body must be JSON like {\"translate\": [x, y, z]} and/or {\"rotate\": {\"axis\": [x, y, z], \"degrees\": d}}, with \"pivot\": [x, y, z] optional";
            let value: serde_json::Value =
                serde_json::from_slice(body).map_err(|e| bad(format!("{shape}: {e}")))?;
            let named = value.get("translate").is_some() || value.get("rotate").is_some();
            let motion: solver::Motion =
                serde_json::from_value(value).map_err(|e| bad(format!("{shape}: {e}")))?;
            if !named {
                return Err(bad(shape.to_string()));
            }
            motion.check().map_err(bad)?;
            Ok(Edit::Move(motion))
        }
    }
}

/// Checks the token and the edit and queues it for the solver thread.
pub fn apply(
    shared: &Shared,
    name: &str,
    field: Field,
    authorization: Option<&str>,
    body: &[u8],
) -> Reply {
    if !authorized(authorization, &shared.token) {
        return Reply::refusal(StatusCode::UNAUTHORIZED, "missing or wrong bearer token");
    }
    if let Some(why) = shared.health.stopped() {
        return Reply::refusal(StatusCode::SERVICE_UNAVAILABLE, why);
    }
    match parse_edit(&shared.hub.geometry().model.objects, name, body, field) {
        Ok(edit) => {
            let mut body = serde_json::json!({ "object": name, "status": "queued" });
            match edit {
                Edit::Emission(emission) => {
                    shared.edits.set_emission(name, emission);
                    body["emission"] = serde_json::json!(emission);
                }
                Edit::Move(motion) => {
                    shared.edits.move_object(name, motion);
                    // The move as it will be applied: every field named, defaults included.
                    body["translate"] = serde_json::json!(motion.translate);
                    if let Some(rotate) = motion.rotate {
                        body["rotate"] = serde_json::json!(rotate);
                    }
                    if let Some(pivot) = motion.pivot {
                        body["pivot"] = serde_json::json!(pivot);
                    }
                }
            }
            Reply {
                status: StatusCode::ACCEPTED,
                body,
            }
        }
        Err(refusal) => refusal,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_the_exact_bearer_token_authorizes_and_an_empty_token_nothing() {
        assert!(authorized(Some("Bearer s3cret"), "s3cret"));
        for given in [
            None,
            Some("Bearer s3cre"),
            Some("bearer s3cret"),
            Some("s3cret"),
        ] {
            assert!(!authorized(given, "s3cret"), "{given:?}");
        }
        assert!(!authorized(Some("Bearer "), ""));
    }

    #[test]
    fn an_edit_is_refused_with_the_rule_it_broke() {
        let objects = vec!["lamp".to_string()];
        let parse = |name, body: &str, field| parse_edit(&objects, name, body.as_bytes(), field);
        assert_eq!(
            parse("lamp", r#"{"emission": [1, 2, 3]}"#, Field::Emission),
            Ok(Edit::Emission([1.0, 2.0, 3.0]))
        );
        let status = |r: Result<Edit, Reply>| r.unwrap_err().status;
        assert_eq!(
            status(parse("desk", r#"{"emission": [1, 2, 3]}"#, Field::Emission)),
            StatusCode::NOT_FOUND
        );
        assert_eq!(
            status(parse(
                "lamp",
                r#"{"translate": [1, 2, 3]}"#,
                Field::Emission
            )),
            StatusCode::BAD_REQUEST
        );
        let refused = parse("lamp", r#"{"emission": [-1, 2, 3]}"#, Field::Emission).unwrap_err();
        assert!(
            refused.body["error"]
                .as_str()
                .unwrap()
                .starts_with("emission "),
            "{refused:?}"
        );
    }

    #[test]
    fn a_move_is_a_translation_a_rotation_or_both_and_is_refused_with_what_was_wrong() {
        let objects = vec!["box".to_string()];
        let parse = |body: &str| parse_edit(&objects, "box", body.as_bytes(), Field::Move);
        assert_eq!(
            parse(r#"{"translate": [1, 2, 3]}"#),
            Ok(Edit::Move(solver::Motion {
                translate: [1.0, 2.0, 3.0],
                ..Default::default()
            }))
        );
        let turn = solver::Rotation {
            axis: [0.0, 1.0, 0.0],
            degrees: 30.0,
        };
        assert_eq!(
            parse(r#"{"rotate": {"axis": [0, 1, 0], "degrees": 30}, "pivot": [5, 0, 5]}"#),
            Ok(Edit::Move(solver::Motion {
                rotate: Some(turn),
                pivot: Some([5.0, 0.0, 5.0]),
                ..Default::default()
            }))
        );
        let error = |body: &str| {
            let refused = parse(body).unwrap_err();
            assert_eq!(refused.status, StatusCode::BAD_REQUEST, "{body}");
            refused.body["error"].as_str().unwrap().to_string()
        };
        assert_eq!(
            error(r#"{"rotate": {"axis": [0, 0, 0], "degrees": 30}}"#),
            "rotate axis [0.0, 0.0, 0.0] must be finite and not zero"
        );
        assert_eq!(error(r#"{"pivot": [0, 0, 0]}"#), error("{}"));
        assert!(error("{}").starts_with("body must be JSON like {\"translate\""));
        assert!(
            error(r#"{"translate": [1, 2, 3], "scale": 2}"#).contains("unknown field `scale`"),
            "{}",
            error(r#"{"translate": [1, 2, 3], "scale": 2}"#)
        );
        assert!(error(r#"{"rotate": {"axis": [0, 1, 0]}}"#).contains("missing field `degrees`"));
        assert_eq!(
            error(r#"{"translate": [1, 2, 3], "pivot": [0, 0, 0]}"#),
            "a pivot needs a rotation"
        );
    }
}
