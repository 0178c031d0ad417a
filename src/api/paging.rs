//! The page contract every list endpoint keeps (`GET /v1/jobs`, `GET /v1/rigs`, `GET /v1/songs`):
//! newest first, `limit` 1..=[`MAX_LIMIT`] (default [`DEFAULT_LIMIT`]), and `next_cursor`, the
//! last item's id, sent back as `cursor` for the page after it; absent on the last page. Written
//! once so the lists cannot drift apart.
use super::problem::ApiError;
use std::str::FromStr;

/// Default page size.
pub const DEFAULT_LIMIT: u32 = 20;
/// Largest page size.
pub const MAX_LIMIT: u32 = 100;

/// A list request's checked `limit` and `cursor`.
#[derive(Clone, Copy, Debug)]
pub struct PageRequest<Id> {
    pub limit: u32,
    /// Items older than this one (the cursor).
    pub before: Option<Id>,
}

impl<Id: FromStr> PageRequest<Id> {
    /// Checks the query's `limit` and `cursor`; out of range or not an id is 422 naming the field.
    pub fn parse(limit: Option<u32>, cursor: Option<&str>) -> Result<Self, ApiError> {
        let limit = limit.unwrap_or(DEFAULT_LIMIT);
        if !(1..=MAX_LIMIT).contains(&limit) {
            return Err(invalid("limit", format!("must be within 1..={MAX_LIMIT}")));
        }
        let before = cursor
            .map(Id::from_str)
            .transpose()
            .map_err(|_| invalid("cursor", "must be the next_cursor of a previous page"))?;
        Ok(Self { limit, before })
    }

    /// How many rows to read: one more than the page, which tells whether another page exists.
    pub fn fetch(&self) -> u32 {
        self.limit + 1
    }

    /// The page of `rows` (read with [`Self::fetch`]) and its `next_cursor`.
    pub fn page<T>(&self, mut rows: Vec<T>, id: impl Fn(&T) -> String) -> (Vec<T>, Option<String>) {
        let more = rows.len() > self.limit as usize;
        rows.truncate(self.limit as usize);
        let next = if more { rows.last().map(id) } else { None };
        (rows, next)
    }
}

fn invalid(field: &str, message: impl Into<String>) -> ApiError {
    ApiError::InvalidField {
        field: field.into(),
        message: message.into(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_page_holds_limit_items_and_names_the_next_only_when_there_is_one() {
        let request = PageRequest::<u32>::parse(Some(2), Some("9")).expect("valid");
        assert_eq!(
            (request.limit, request.before, request.fetch()),
            (2, Some(9), 3)
        );
        let name = |n: &u32| n.to_string();
        assert_eq!(
            request.page(vec![8, 7, 6], name),
            (vec![8, 7], Some("7".into()))
        );
        assert_eq!(request.page(vec![8, 7], name), (vec![8, 7], None));
        let default = PageRequest::<u32>::parse(None, None).expect("defaults");
        assert_eq!((default.limit, default.before), (DEFAULT_LIMIT, None));
        for (limit, cursor, field) in [
            (Some(0), None, "limit"),
            (Some(MAX_LIMIT + 1), None, "limit"),
            (None, Some("nope"), "cursor"),
        ] {
            match PageRequest::<u32>::parse(limit, cursor) {
                Err(ApiError::InvalidField { field: f, .. }) => assert_eq!(f, field),
                other => panic!("{limit:?} {cursor:?}: {other:?}"),
            }
        }
    }
}
