"""API keys with scopes: who may read, write or administer which collections."""
