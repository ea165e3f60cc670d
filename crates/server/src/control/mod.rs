//! The control API as plain functions: check the token, parse `{"FIELD": [a, b, c]}`, queue
//! the edit. The HTTP route calls [`apply`] on the origin; on an edge the same request travels
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
    /// `PUT /api/objects/{name}/transform` with `{"translate": [x, y, z]}` (scene units).
    Move,
}

impl Field {
    /// The JSON key of the body.
    pub fn key(self) -> &'static str {
        match self {
            Field::Emission => "emission",
            Field::Move => "translate",
        }
    }

    /// The field whose JSON key is `key`.
    pub fn from_key(key: &str) -> Option<Field> {
        [Field::Emission, Field::Move]
            .into_iter()
            .find(|f| f.key() == key)
    }

    /// The solver's rule for the values.
    fn check(self) -> fn([f64; 3]) -> Result<(), String> {
        match self {
            Field::Emission => solver::check_emission,
            Field::Move => solver::check_translation,
        }
    }
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

/// Checks an edit: the object exists and the body is `{"FIELD": [a, b, c]}` with values the
/// solver's rule for the field accepts. Returns the triple or the refusal.
pub fn parse_edit(
    objects: &[String],
    name: &str,
    body: &[u8],
    field: Field,
) -> Result<[f64; 3], Reply> {
    if !objects.iter().any(|o| o == name) {
        return Err(Reply::refusal(
            StatusCode::NOT_FOUND,
            format!("no object named '{name}'"),
        ));
    }
    let key = field.key();
    let shape = || format!("body must be JSON like {{\"{key}\": [a, b, c]}}");
    let value: serde_json::Value = serde_json::from_slice(body)
        .map_err(|e| Reply::refusal(StatusCode::BAD_REQUEST, format!("{}: {e}", shape())))?;
    let object = value
        .as_object()
        .filter(|o| o.len() == 1)
        .ok_or_else(|| Reply::refusal(StatusCode::BAD_REQUEST, shape()))?;
    let triple: [f64; 3] = object
        .get(key)
        .and_then(|v| serde_json::from_value(v.clone()).ok())
        .ok_or_else(|| Reply::refusal(StatusCode::BAD_REQUEST, shape()))?;
    field.check()(triple)
        .map_err(|rule| Reply::refusal(StatusCode::BAD_REQUEST, format!("{key} {rule}")))?;
    Ok(triple)
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
        Ok(value) => {
            match field {
                Field::Emission => shared.edits.set_emission(name, value),
                Field::Move => shared.edits.move_object(name, value),
            }
            let mut body = serde_json::json!({ "object": name, "status": "queued" });
            body[field.key()] = serde_json::json!(value);
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
            Ok([1.0, 2.0, 3.0])
        );
        let status = |r: Result<[f64; 3], Reply>| r.unwrap_err().status;
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
}
