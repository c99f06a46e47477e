"""Interactive offline HTML reports and the live page of ``run --web`` (adapter layer: dicts in, pages and an
HTTP server out; our own plotting module, no third-party JavaScript)."""
