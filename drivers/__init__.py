"""Device drivers: one folder per device, each a sans-I/O codec and an asyncio session.

The devices: VN-200, µADC, surface box, XBee, autopilot; DESIGN.md has the layout they
follow.
"""
