# field_log tests (placeholder, owned by the field_log work)
