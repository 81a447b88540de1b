# config tests (placeholder, owned by the config work)
