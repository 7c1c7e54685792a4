from simfab.cli import entry

entry()
