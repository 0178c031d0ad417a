//! HTTP API: routes, handlers, problem+json errors and the OpenAPI document.
