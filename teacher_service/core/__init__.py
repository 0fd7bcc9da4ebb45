"""The service's configuration: settings read from defaults, ``KC_`` environment variables and flags."""
