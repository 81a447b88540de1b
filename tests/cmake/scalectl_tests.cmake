# scalectl tests (placeholder, owned by the scalectl work)
