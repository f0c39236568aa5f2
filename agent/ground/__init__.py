"""The ground console: the operator's end of the XBee link (`sysid console`)."""
