"""Pictures and the shareable report: headless renders (``render``), colours (``colors``),
the self-contained HTML page (``report``)."""
