"""The fleet report of `flightctl diagnose --corpus DIR --fleet REPORT` (docs/fleet.md, "The fleet
report"): each log's figures (`figures`, kept in the results table's row), the logs grouped by vehicle
and put in flight order (`grouping`), each vehicle's series tested for a change (`trends`), and the
report's table and JSON (`report`) and a figure per vehicle (`figure`)."""
