"""The ``nlsid`` command line: one thin module per subcommand (parse, call the library, write, print)."""
