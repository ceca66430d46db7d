"""The top floor: the three commands' thin layers, the demo, the trade-off's command, reports and plots. The one folder of fitgen that imports host and hil."""
