def pytest_configure(config):
    config.addinivalue_line(
        "markers", "fuzz: unusual-value images through every effect and look (tests/fuzz; "
                   "about a minute; deselect with -m 'not fuzz')")
